"""hnn.threads: a block's torch thread count, the caller's back however the block ends."""
import pytest
import torch

from hnn.threads import cores, torch_threads


def test_a_blocks_thread_count_is_its_own_and_the_callers_returns_even_on_an_error():
    caller = torch.get_num_threads()
    other = 2 if caller == 1 else 1
    with torch_threads(other):
        assert torch.get_num_threads() == other
        with torch_threads(None):                       # None: left as the block outside set it
            assert torch.get_num_threads() == other
    assert torch.get_num_threads() == caller
    with pytest.raises(KeyError), torch_threads(other):
        raise KeyError("a failure inside the block")
    assert torch.get_num_threads() == caller
    with pytest.raises(ValueError, match="at least 1"), torch_threads(0):
        pass
    assert torch.get_num_threads() == caller and cores() >= 1
