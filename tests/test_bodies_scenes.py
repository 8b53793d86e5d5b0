"""The scenes of many bodies in the scene study: their own page, their energy protocols (the true H conserved along
the true paths), the rungs that fit them (the pair kind's; H's library refused by its size, by name), and a learned
path inside the Lennard-Jones wall scored as a failed rollout."""
import dataclasses
import math

import numpy as np
import pytest
import torch

import hnn
from hnn.fits import features
from hnn_analysis.scenes import scene_common, scene_study

BODY_SCENES = ("gravity", "lattice", "lj")


def test_the_scenes_of_bodies_are_a_page_of_their_own_and_the_paper_study_is_unchanged():
    assert set(scene_common.scenes("bodies")) == set(BODY_SCENES)
    assert not set(BODY_SCENES) & set(scene_common.scenes())      # the default study: the paper's page
    assert set(scene_common.scenes(None)) == set(scene_common.scenes()) | set(BODY_SCENES)
    # a page's files and sections never collide with another's
    for key in ("stem", "figure"):
        assert len({page[key] for page in scene_common.PAGES.values()}) == len(scene_common.PAGES)
    sections = [name for page in scene_common.PAGES.values() for name in page["sections"]]
    assert len(set(sections)) == len(sections)


def test_a_study_writes_one_pages_cards_or_says_the_fix(capsys):
    with pytest.raises(SystemExit):
        scene_study.main(["--scenes", "gravity", "spring"])
    assert "mixes the scenes of the pages" in capsys.readouterr().err


@pytest.mark.parametrize("task", BODY_SCENES)
def test_each_scene_of_bodies_has_the_pair_rungs_and_not_hs_library(task):
    rungs = scene_common.task_rungs(task)
    assert {"pairwise", "pairwise+swim", "pairwise+library", "hnn", "baseline"} <= set(rungs)
    assert "hnn+library" not in rungs
    # the page leaves SINDy's 6545 terms out, and says why where it writes its cards
    assert "baseline+sindy" not in rungs and "baseline+sindy" in scene_common.PAGES["bodies"]["left_out"]
    if hnn.fits.sindy.version() is not None:      # SINDy's rung needs pysindy (the sindy extra)
        assert "baseline+sindy" in scene_common.task_rungs("3body")    # the paper's page keeps it
    config = hnn.tasks.task_config(task, {"model": "hnn", "fit": "library"})
    with pytest.raises(features.LibraryTooLargeError, match=r"63800 terms.*--model pairwise --fit library"):
        hnn.kinds.model_from_spec(hnn.specs.run_specs(config).model)


def test_the_library_counts_its_terms_without_listing_them_and_refuses_past_its_bytes():
    for width in (2, 4, 6, 12):
        for form in features.Library.forms:
            for degree in (1, 2, 3):
                for frequencies in (0, 1, 2):
                    for products in (True, False):
                        assert features.term_count(width, form, degree, frequencies, products) == \
                            len(features.terms(width, form, degree, frequencies, products)), (width, form, degree)
    # H's cubic library on the 12 columns of the 3-body (the paper's task) stays far within the limit
    assert 8 * features.term_count(12, "hamiltonian", 3, 1) ** 2 < features.LIBRARY_BYTES / 100
    # the limit is the (terms, terms) float64 matrix's: 23170 terms fit 4 GiB, 23171 do not
    assert math.isqrt(features.LIBRARY_BYTES // 8) == 23170


@pytest.mark.parametrize("task", BODY_SCENES)
def test_each_scenes_energy_protocol_keeps_the_true_h_along_the_true_paths(task):
    system = hnn.load_task(task)
    protocol = hnn.task_spec(task).protocols["corrected"]
    result = hnn.evaluate_energy(system, {}, protocol, progress=False)
    energy = result["energy_truth"]                 # (trials, T), the true H of each true path
    assert energy.shape == (protocol.num_trials, protocol.num_points)
    # DOP853 at rtol 1e-9 over the span: the drift is the tolerance's, far below the energies' own spread
    drift = np.abs(energy - energy[:, :1]).max()
    assert drift < 1e-5 * max(1.0, np.abs(energy).max()), drift
    assert np.ptp(energy[:, 0]) > 100 * drift      # the 15 starts differ: a drift this small is not a constant H
    # H reads any leading shape: a batch, or trials x times
    x = torch.as_tensor(result["truth"])
    assert torch.allclose(system.hamiltonian(x), system.hamiltonian(x.reshape(-1, x.shape[-1])).reshape(x.shape[:-1]))


def test_a_learned_path_inside_the_lennard_jones_wall_is_a_failed_rollout_not_a_number():
    data = hnn.load_task("lj")
    assert issubclass(data.WallError, hnn.DivergenceError) and issubclass(data.WallError, ValueError)
    # a field that drives body 1 left at speed 5 (dq_x1/dt = -5, all else 0): within the protocol's 5 time units
    # it passes through body 0, about 1.12 to its left
    config = hnn.tasks.task_config("lj", {"model": "baseline", "hidden_dim": 8})
    model = hnn.kinds.model_from_spec(hnn.specs.run_specs(config).model)
    with torch.no_grad():
        for p in model.parameters():
            p.zero_()
        net = model.differentiable_model
        net.linear2.bias.fill_(1.0)
        net.linear3.weight[1].fill_(-5.0 / (8 * math.tanh(1.0)))
    x0 = torch.as_tensor(data.initial_state(0), dtype=torch.float32)[None]
    expected = torch.zeros_like(x0)
    expected[0, 1] = -5.0
    assert torch.allclose(model.time_derivative(x0), expected, atol=1e-6)
    protocol = dataclasses.replace(hnn.task_spec("lj").protocols["corrected"], num_trials=5)
    result = hnn.evaluate_energy(data, {"toward": model}, protocol, progress=False)
    # scored as a path that blew up is: no energy MSE, and why (the pair, inside the wall), never an overflow
    assert result["toward"]["mse"] is None
    assert "bodies 0 and 1" in result["toward"]["why"] and "wall" in result["toward"]["why"]


def test_failed_rollouts_read_as_one_line_a_model_and_a_shared_reason_as_one_line():
    from hnn_analysis.scenes import scene_tables

    def seeds(*whys):
        return {"per_seed": {str(i): {"energy_not_applicable": {"corrected": why}} for i, why in enumerate(whys)}}
    results = {"scenes": {"lj": {"kinds": {
        "hnn": seeds("bodies 2 and 4 of state 9 are 0.5 apart", "bodies 1 and 3 of state 7 are 0.1 apart"),
        "g_sympnet": seeds("a map", "a map"), "henon": seeds("a map")}}}}
    lines = [line for line in scene_tables.not_applicable_lines(results) if line.startswith("- ")]
    assert lines == ["- lj, corrected protocol, hnn: bodies 2 and 4 of state 9 are 0.5 apart (the first of 2 seeds)",
                     "- lj, corrected protocol, g_sympnet, henon: a map"]
