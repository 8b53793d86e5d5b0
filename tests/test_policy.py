"""A run's policy is resolved in one place (``hnn.policy.prepare``, and the same resolvers in ``hnn.train``'s
front door): a rule changed there reaches a lone run, a group's members and ``hnn.train`` alike; and no
library call leaves the caller's global random state changed."""
import json

import numpy as np
import pytest
import torch

import hnn
import hnn.balance
from hnn.sweeps.group_runs import train_group, unit_key

TINY = {"hidden_dim": 8, "total_steps": 5}


def _configs(save_dir, seeds=(0, 1)):
    return [hnn.tasks.task_config("spring", {**TINY, "seed": s, "save_dir": str(save_dir)}) for s in seeds]


def _weights(folder):
    return json.loads((folder / "args.json").read_text()).get("loss_weights")


@pytest.mark.parametrize("ratio, balanced", [(hnn.balance.AUTO_RATIO, False), (0.0, True)],
                         ids=["as-shipped", "rule-changed"])
def test_the_balance_rule_changed_in_one_place_reaches_a_lone_run_a_group_and_hnn_train(ratio, balanced, tmp_path,
                                                                                        monkeypatch):
    # the spring's dq/dt and dp/dt are of one size (ratio about 1): 'auto' leaves its loss plain at the shipped
    # threshold, and balances it once the threshold is below the ratio
    monkeypatch.setattr(hnn.balance, "AUTO_RATIO", ratio)
    lone_config, *group_configs = _configs(tmp_path / "lone", seeds=(0,)) + _configs(tmp_path / "group")
    assert unit_key(group_configs[0]) is not None          # a group by its key: the resolver decides what trains alone
    data = lone_config.dataset()
    lone = hnn.run_experiment(lone_config, data)
    group = train_group(group_configs)
    model = hnn.HNN(2, hnn.MLP(2, 8, 2))
    stats = hnn.train(model, data["x"], data["dxdt"], total_steps=2, progress=False)

    found = [_weights(lone), *(_weights(f) for f in group), stats.get("loss_weights")]
    if not balanced:
        assert found == [None] * 4
        assert json.loads((group[0] / "metrics.json").read_text())["history"]["group_size"] == 2
        return
    assert all(w is not None for w in found), found
    # each weight is its component's 1/RMS over the whole training set, the same rows in all three paths
    expected = hnn.balance.balance_weights(data["dxdt"], "auto", "l2")
    for weights in (found[0], found[3]):
        np.testing.assert_allclose(weights, expected, rtol=1e-6)       # float32 round trip of the weights
    # a balanced loss is what a group's program does not do: each member trained alone, as its lone run
    assert all("group_size" not in json.loads((f / "metrics.json").read_text())["history"] for f in group)


def test_no_run_leaves_the_callers_random_state_changed(tmp_path):
    torch.manual_seed(123)
    np.random.seed(123)
    hnn.run_experiment(_configs(tmp_path / "lone", seeds=(4,))[0])
    train_group(_configs(tmp_path / "group"))
    after = torch.rand(3), np.random.rand(3)
    torch.manual_seed(123)
    np.random.seed(123)
    assert torch.equal(after[0], torch.rand(3)) and np.array_equal(after[1], np.random.rand(3))


def test_a_step_callback_is_an_argument_and_stops_a_run_by_raising(tmp_path):
    calls = []

    class Stop(Exception):
        pass

    def stop_at_3(done, total):
        calls.append((done, total))
        if done == 3:
            raise Stop
    config = _configs(tmp_path, seeds=(0,))[0]
    with pytest.raises(Stop):
        hnn.run_experiment(config, on_step=stop_at_3)
    assert calls == [(1, 6), (2, 6), (3, 6)] and hnn.runs.find_run(config) is None
    hnn.run_experiment(config)          # no callback left behind: the next run trains to its end
    assert len(calls) == 3 and hnn.runs.find_run(config) is not None
