"""A run's typed specs (hnn.specs): derived once from the config or from a saved run's args, and the
same either way; each field reaches its consumer by attribute (input_noise, from the 2-body flag to
hnn.train's noise); an old run's args without a field read as the value that run trained with."""
import dataclasses
import inspect

import numpy as np
import pytest
import torch

import hnn


def test_training_spec_is_hnn_trains_keywords():
    params = inspect.signature(hnn.train).parameters
    for f in dataclasses.fields(hnn.specs.TrainingSpec):
        assert params[f.name].kind is inspect.Parameter.KEYWORD_ONLY, f.name
        assert params[f.name].default == f.default, f.name         # a saved run lacking it trained with this


def test_a_saved_run_reads_back_to_the_specs_of_its_config(tmp_path):
    trainer = hnn.load_task("2body", "train")
    argv = ["--total_steps", "2", "--hidden_dim", "8", "--input_noise", "0.25", "--save_dir", str(tmp_path)]
    config = hnn.cli.parse(trainer.Config, argv)
    specs = hnn.specs.run_specs(config)
    assert specs.objective.input_noise == 0.25 and specs.training.total_steps == 2
    # the 2-body task declares its bodies (model_facts), which the pair kind reads
    assert specs.model == hnn.kinds.ModelSpec("hnn", input_dim=8, hidden_dim=8, init="orthogonal",
                                              bodies=hnn.bodies.Bodies(2, 2).to_dict())
    _, saved, _ = hnn.load_run(trainer.main(argv))
    # args.json holds more keys: the specs pick theirs, and the data's time step that only a run knows
    assert saved["dt"] == config.dataset()["dt"]
    assert hnn.specs.run_specs(saved) == dataclasses.replace(specs, model=dataclasses.replace(specs.model,
                                                                                            dt=saved["dt"]))


def test_an_old_run_without_a_field_reads_as_it_trained():
    old = {"kind": "hnn", "input_dim": 2, "seed": 3}        # saved before balance, input_noise, optimizer existed
    specs = hnn.specs.run_specs(old)
    assert specs.objective == hnn.specs.ObjectiveSpec(seed=3, input_noise=0.0, use_rk4=False, derivative_loss="l2",
                                                     balance="off")
    assert (specs.training.optimizer, specs.training.schedule, specs.training.clip_grad) == ("adam", "constant", 0.0)
    with pytest.raises(TypeError, match="RunConfig or a run's saved args"):
        hnn.specs.run_specs(["kind", "hnn"])


def test_input_noise_goes_from_the_flag_to_the_training_batches(monkeypatch, tmp_path):
    """The 2-body flag's value arrives as the loop's input_noise, read off the objective's spec (no dict)."""
    seen = {}
    real = hnn.trainers.lone.run_loop          # the lone loop a prepared run trains through

    def spy(model, *arrays, **options):
        seen.update(options)
        return real(model, *arrays, **options)
    monkeypatch.setattr(hnn.trainers.lone, "run_loop", spy)
    hnn.load_task("2body", "train").main(["--total_steps", "1", "--hidden_dim", "8", "--input_noise", "0.5",
                                          "--save_dir", str(tmp_path)])
    assert seen["input_noise"] == 0.5 and seen["total_steps"] == 1


def test_the_objectives_read_the_spec_by_attribute():
    model = hnn.build_model(2, 8)
    data = {"x": np.ones((4, 2), np.float32), "dxdt": np.ones((4, 2), np.float32), "dt": 0.1}
    spec = hnn.specs.ObjectiveSpec(input_noise=0.5, use_rk4=True, derivative_loss="l1")
    options = hnn.DerivativeObjective().train_options(model, spec, data)
    assert options.input_noise == 0.5 and options.derivative_loss == "l1" and options.predict is not None
    x = torch.ones(3, 2)
    torch.testing.assert_close(options.predict(x), hnn.integrators.rk4_step(model.time_derivative, x, 0.1) / 0.1)
    with pytest.raises(dataclasses.FrozenInstanceError):     # a record of one run's options, not state to change
        options.input_noise = 0.0
