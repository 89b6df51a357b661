"""geo.train / geo.resume from Python: the trainer geo_train runs, a per-step callback, Ctrl-C with
geo_train's checkpoint guarantee, configs as dicts, and the weights as PyTorch state dicts."""
import os
import signal

import pytest
import torch

import geo
from conftest import TINY_RUN


def test_training_reports_every_step_and_writes_the_run(trained):
    run, steps = trained
    assert [(s["stage"], s["iteration"], s["global_step"]) for s in steps] == [
        ("stage1", 1, 1), ("stage1", 2, 2), ("stage2", 1, 3), ("stage2", 2, 4)]
    assert all(s["stage_iterations"] == 2 and s["lr"] == pytest.approx(2e-4) for s in steps)
    assert set(steps[0]["losses"]) >= {"total", "rigid"} and "flow" in steps[2]["losses"]
    assert all(torch.isfinite(torch.tensor(s["losses"]["total"])) for s in steps)
    assert (run / "checkpoints" / "best-stage2.pt").is_file()
    assert (run / "metrics.csv").read_text().count("\n") == 5  # header + 4 steps


def test_a_callback_that_raises_stops_the_run_with_its_exception(tmp_path):
    calls = []

    def callback(step):
        calls.append(step["global_step"])
        raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        geo.train("smoke.yaml", run_dir=str(tmp_path / "run"), overrides=TINY_RUN, callback=callback)
    assert calls == [1]
    assert not list((tmp_path / "run" / "checkpoints").glob("*.pt"))  # a sink's exception: no checkpoint


def test_sigint_writes_a_checkpoint_and_resume_finishes(tmp_path):
    run = tmp_path / "run"

    def interrupt(step):
        if step["global_step"] == 1:
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt, match="geo.resume"):
        geo.train("smoke.yaml", run_dir=str(run), overrides=TINY_RUN, callback=interrupt)
    assert (run / "checkpoints" / "stage1-00000001.pt").is_file()
    # Python's own SIGINT handling is back once training returns.
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    seen = []
    assert geo.resume(str(run), callback=seen.append) == str(run)
    assert [s["global_step"] for s in seen] == [2, 3, 4]
    assert (run / "checkpoints" / "best-stage2.pt").is_file()


def test_configs_as_dicts_and_their_errors(tmp_path):
    config = {"model": {"encoder_depth": 18}, "data": {"format": "synthetic", "height": 64, "width": 208},
              "stages": [{"name": "only", "iterations": 1, "train": ["depth", "pose"], "batch_size": 1}],
              "logging": {"interval": 1, "val_interval": 0, "summary_interval": 0, "checkpoint_interval": 1},
              "run": {"threads": 1}}
    seen = []
    run = geo.train(config, run_dir=str(tmp_path / "dict"), overrides=["data.synthetic.drives=1",
                    "data.synthetic.frames_per_drive=4"], callback=seen.append)
    assert len(seen) == 1 and (tmp_path / "dict" / "checkpoints" / "only-00000001.pt").is_file() and run
    config["model"]["encoder_depht"] = 50
    with pytest.raises(geo.ConfigError, match="encoder_depht"):
        geo.train(config, run_dir=str(tmp_path / "bad"))
    with pytest.raises(geo.ConfigError, match="no_such_config"):
        geo.train("no_such_config.yaml", run_dir=str(tmp_path / "bad"))
    assert not (tmp_path / "bad").exists()


def test_state_dicts_hold_every_weight_and_survive_a_model_file(trained, model_file):
    run, _ = trained
    from_run = geo.state_dicts(str(run))
    from_file = geo.state_dicts(str(model_file))
    assert from_run["spec"]["model"]["encoder_depth"] == 18
    for net in ("depth", "pose", "flow"):
        assert list(from_run[net]) == list(from_file[net]) and len(from_run[net]) > 10
        for name, tensor in from_run[net].items():
            assert torch.equal(tensor, from_file[net][name]), f"{net}.{name}"
    # The weights the model computes with: a different weight, a different depth.
    assert any(name.endswith("running_mean") for name in from_run["depth"])
