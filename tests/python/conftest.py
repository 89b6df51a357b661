"""Fixtures of geo's Python tests: a model trained from Python for two steps per stage on the
in-memory synthetic world, its geo_export-style file, and a small geo_synth world on disk.

ctest runs this suite with PYTHONPATH=<build>/python and GEO_APPS_DIR=<build>/apps; by hand:
    PYTHONPATH=build/python GEO_APPS_DIR=build/apps python3 -m pytest tests/python
"""
import os
import pathlib
import subprocess

import pytest

import geo

APPS = pathlib.Path(os.environ.get("GEO_APPS_DIR", pathlib.Path(__file__).resolve().parents[2] / "build" / "apps"))

# As the Apps.GeoTrainOnTheInMemoryWorld test: both stages, two iterations each, every artefact.
TINY_RUN = ["data.format=synthetic", "data.synthetic.drives=1", "data.synthetic.frames_per_drive=8",
            "stages.0.iterations=2", "stages.1.iterations=2", "logging.interval=1", "logging.val_interval=2",
            "logging.checkpoint_interval=2", "logging.summary_interval=2", "run.threads=1"]


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
    run = geo.train("smoke.yaml", run_dir=str(tmp_path_factory.mktemp("train") / "run"), overrides=TINY_RUN,
                    callback=steps.append)
    return pathlib.Path(run), steps


@pytest.fixture(scope="session")
def model_file(trained, tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "model.pt"
    geo.Model.load(str(trained[0])).save(str(path))
    return path


@pytest.fixture(scope="session")
def model(model_file):
    return geo.Model.load(str(model_file))


@pytest.fixture(scope="session")
def world_dir(tmp_path_factory):
    """A geo_synth world: one training and one test drive of 6 frames, 2 flow pairs, 12 odometry frames."""
    root = tmp_path_factory.mktemp("world") / "w"
    run_app("geo_synth", "--out", root, "--drives", 1, "--test-drives", 1, "--frames", 6, "--flow-pairs", 2,
            "--odometry-frames", 12, "--threads", 1)
    return root
