"""The layout of a state as bodies (hnn.bodies.Bodies) and the tasks that declare theirs: the original's order of
the orbit tasks' columns, read back exactly."""
import pytest
import torch

from hnn.bodies import Bodies
from hnn.tasks import task_config


def test_bodies_read_the_original_order():
    # the 3-body's state is [qx_1..qx_3, qy_1..qy_3, px_1..px_3, py_1..py_3] (experiment-3body/data.py)
    layout = task_config("3body").BODIES
    x = torch.arange(12.0)[None]
    q, p = layout.split(x)
    assert q[0, :, 0].tolist() == [0.0, 1.0, 2.0] and q[0, :, 1].tolist() == [3.0, 4.0, 5.0]
    assert p[0, 2].tolist() == [8.0, 11.0]
    assert torch.equal(layout.join(q, p), x)
    body = Bodies(3, 2, order="body")
    qb, _ = body.split(x)
    assert qb[0, 1].tolist() == [2.0, 3.0]
    assert torch.equal(body.join(*body.split(x)), x)


def test_tasks_declare_their_bodies():
    for task, count in (("2body", 2), ("3body", 3)):
        config = task_config(task)
        facts = config.model_facts()["bodies"]
        assert Bodies.from_dict(facts) == Bodies(count, 2)
        assert Bodies.from_dict(facts).width == config.input_dim


def test_bodies_refuse_bad_declarations():
    with pytest.raises(ValueError, match="dim"):
        Bodies(3, 4)
    with pytest.raises(ValueError, match="species"):
        Bodies(3, 2, species=(0, 1))
    with pytest.raises(ValueError, match="width"):
        Bodies(3, 2).count_of(10)
    with pytest.raises(ValueError, match="which is which"):
        Bodies(3, 2, species=(0, 0, 1)).labels(5)
