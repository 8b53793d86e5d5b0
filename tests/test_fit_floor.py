"""The fit-floor benchmark's arithmetic (analysis/fits/floor.py): the flops it charges each call against the
textbook counts, and the page's word on the box's load read from other processes' cores, not from a load
average that counts the command's own threads."""
import pytest

from hnn_analysis.fits.floor import flops, section


def test_the_floor_charges_each_call_its_textbook_flops():
    assert flops("mm", (3, 4, 5)) == 2 * 3 * 4 * 5
    # Householder QR of m x n (m >= n): 2 m n^2 - 2 n^3 / 3, the same for the transposed shape
    assert flops("qr", (100, 10)) == flops("qr", (10, 100)) == pytest.approx(2 * 100 * 100 - 2 * 1000 / 3)
    assert flops("svd", (7, 9)) == 22 * 7 ** 3
    assert flops("trsm", (6, 6, 2)) == 36 * 2
    # a square triangle folded into another (k = n): the QR of the stacked 2n x n's upper part, 2/3 n^3
    assert flops("tpqrt", (30, 30)) == pytest.approx(2 * 30 ** 3 / 3)


def _results(others, load=(1.9, 2.0)):
    row = {"label": "a fit", "threads": 2, "rows": 10, "each": [1.0], "seconds": 1.0, "floor": 0.5, "ratio": 2.0,
           "gflop": 1.0, "gemm_floor": 0.01, "main": ["qr 10x2 (1x)"], "peak_gib": 0.1}
    meta = {"date": "2026-12-06", "commit": "abc1234", "cores": 2, "torch": "2.13.0", "command": "fit_floor.py",
            "cpu_flags": "avx512f"}
    results = {"meta": meta, "repeats": 1, "rows": [row], "load": list(load), "gemm_gflops": {1: 70.0}}
    if others is not None:
        results["others"] = others
    return results


def test_the_page_calls_the_box_loaded_by_other_processes_cores_not_its_own_threads():
    # a two-thread fit lifts the load average to 2 by itself: with other processes idle the box was quiet
    quiet = section(_results(others=0.0))
    assert "loaded box" not in quiet and "other processes kept 0.0 cores busy" in quiet
    assert "other processes kept 1.3 of 2 cores busy" in section(_results(others=1.3))
    # a run saved before it recorded the others' cores: the load average decides, as it did
    assert "load average 1.9 on 2 cores" in section(_results(others=None))
