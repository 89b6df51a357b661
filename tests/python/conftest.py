"""Fixtures of geo's Python tests: a model trained from Python for two steps per stage on the
in-memory synthetic world, its geo_export-style file, and a small geo_synth world on disk.

ctest runs this suite with PYTHONPATH=<build>/python and GEO_APPS_DIR=<build>/apps; by hand:
    PYTHONPATH=build/python GEO_APPS_DIR=build/apps python3 -m pytest tests/python
"""
import os
import pathlib
import shutil
import subprocess

import pytest

import geo

APPS = pathlib.Path(os.environ.get("GEO_APPS_DIR", pathlib.Path(__file__).resolve().parents[2] / "build" / "apps"))

# As the Apps.GeoTrainOnTheInMemoryWorld test: both stages, two iterations each, every artefact.
TINY_RUN = ["data.format=synthetic", "data.synthetic.drives=1", "data.synthetic.frames_per_drive=8",
            "stages.0.iterations=2", "stages.1.iterations=2", "logging.interval=1", "logging.val_interval=2",
            "logging.checkpoint_interval=2", "logging.summary_interval=2", "run.threads=1"]


# Checkpoints of a run take hundreds of megabytes: what a passing test wrote is removed when it ends,
# a failing test's folder stays for inspection (GEO_KEEP_TEST_DIRS=1 keeps every folder).
KEEP = os.environ.get("GEO_KEEP_TEST_DIRS") == "1"


@pytest.hookimpl(tryfirst=True, hookwrapper=True)
def pytest_runtest_makereport(item, call):
    report = (yield).get_result()
    setattr(item, "geo_failed_" + report.when, report.failed)


@pytest.fixture(autouse=True)
def _remove_tmp_path_of_passing_tests(request):
    path = request.getfixturevalue("tmp_path") if "tmp_path" in request.fixturenames else None
    yield
    failed = any(getattr(request.node, "geo_failed_" + when, False) for when in ("setup", "call"))
    if path is not None and not failed:
        remove_folder(path)


def remove_folder(path):
    if not KEEP:
        shutil.rmtree(path, ignore_errors=True)


def app(name):
    path = APPS / name
    if not path.exists():
        pytest.skip(f"{name} is not built (a build without OpenCV has no {name})")
    return str(path)


def run_app(name, *args):
    result = subprocess.run([app(name), *map(str, args)], capture_output=True, text=True)
    assert result.returncode == 0, f"{name} {' '.join(map(str, args))} failed:\n{result.stdout}\n{result.stderr}"
    return result


@pytest.fixture(scope="session")
def trained(tmp_path_factory):
    """(run folder, the steps the callback saw) of a training from Python."""
    steps = []
    folder = tmp_path_factory.mktemp("train")
    run = geo.train("smoke.yaml", run_dir=str(folder / "run"), overrides=TINY_RUN, callback=steps.append)
    yield pathlib.Path(run), steps
    remove_folder(folder)


@pytest.fixture(scope="session")
def model_file(trained, tmp_path_factory):
    folder = tmp_path_factory.mktemp("model")
    path = folder / "model.pt"
    geo.Model.load(str(trained[0])).save(str(path))
    yield path
    remove_folder(folder)


@pytest.fixture(scope="session")
def model(model_file):
    return geo.Model.load(str(model_file))


@pytest.fixture(scope="session")
def world_dir(tmp_path_factory):
    """A geo_synth world: one training and one test drive of 6 frames, 2 flow pairs, 12 odometry frames."""
    folder = tmp_path_factory.mktemp("world")
    root = folder / "w"
    run_app("geo_synth", "--out", root, "--drives", 1, "--test-drives", 1, "--frames", 6, "--flow-pairs", 2,
            "--odometry-frames", 12, "--threads", 1)
    yield root
    remove_folder(folder)
