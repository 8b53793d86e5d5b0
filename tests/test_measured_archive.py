"""The files of Schmidt & Lipson's archive (invar_datasets.zip, 15 text files) as they come, read by
experiment-measured's reader: every layout the archive uses, rebuilt here from its facts (header
line, columns, trials, number format, line endings), since the repository must not depend on the
archive; an unwrapped angle read as a position gets the hint to pass --periodic."""
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hnn
from hnn_analysis.scenes import measured_study

REPO = Path(__file__).resolve().parent.parent
reader = hnn.load_task("measured", "reader")
data = hnn.load_task("measured")

# (member, its header line verbatim, trials, rows per trial, number style, trailing unnamed derivative columns)
# "sci": 25-wide %.16e with three exponent digits, as most members; "plain": shortest repr, as two members.
ARCHIVE = [
    ("circle_1.txt", "% x y", 1, 360, "sci", False),
    ("double_linear_h_1.txt", "% x1 x2 v1 v2", 1, 821, "sci", True),
    ("double_pend_h_1.txt", "%o1 o2 w1 w2", 2, 1258, "sci", True),
    ("lienar_a_1.txt", "x v a", 1, 512, "sci", False),
    ("linear_h_1.txt", "% x v", 1, 512, "sci", False),
    ("pendulum_a_1.txt", "% o a", 1, 493, "sci", True),
    ("pendulum_h_1.txt", "% o v", 1, 493, "sci", True),
    ("real_double_linear_h_1.txt", "% x1 x2 v1 v2", 1, 495, "sci", False),
    ("real_double_pend_h_1.txt", "% o1 o2 w1 w2", 2, 760, "plain", True),
    ("real_linear_a_1.txt", "% x a v", 1, 870, "sci", False),
    ("real_linear_h_1.txt", "% x v", 1, 870, "sci", False),
    ("real_pend_a_1.txt", "% o a w", 1, 556, "sci", False),
    ("real_pend_circle_1.txt", "% x y", 1, 600, "plain", False),
    ("real_pend_h_1.txt", "%o v", 1, 556, "sci trailing space", False),
    ("sphere_1.txt", "% x y z", 2, 1000, "sci", False),
]


def _cell(value: float, style: str) -> str:
    if style.startswith("plain"):
        return repr(float(value))
    mantissa, exponent = f"{value:.16e}".split("e")
    return f"{mantissa}e{exponent[0]}{int(exponent[1:]):03d}".rjust(25)


def _write_member(path: Path, header: str, trials: int, rows: int, style: str, derivatives: bool) -> np.ndarray:
    """A file in the member's layout: trial, t, the named columns (oscillations of known derivative), then
    with ``derivatives`` d/dt of each named column; returns the values written ``(rows, cells)``."""
    n = len(header.lstrip("%").split())
    out = []
    for k in range(trials):
        t = 0.01 * np.arange(rows)
        w = 1.0 + 0.5 * np.arange(n)                      # column j: sin(w_j t + k), d/dt = w_j cos(w_j t + k)
        cols = [np.full(rows, float(k)), t] + [np.sin(w[j] * t + k) for j in range(n)]
        if derivatives:
            cols += [w[j] * np.cos(w[j] * t + k) for j in range(n)]
        out.append(np.stack(cols, axis=1))
    values = np.concatenate(out)
    tail = " " if "trailing" in style else ""
    sep = " " if style.startswith("plain") else ""
    lines = [header] + [sep.join(_cell(v, style) for v in row) + tail for row in values]
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return values


@pytest.mark.parametrize("member, header, trials, rows, style, derivatives", ARCHIVE, ids=[a[0] for a in ARCHIVE])
def test_every_member_of_the_archive_reads_as_published(tmp_path, member, header, trials, rows, style, derivatives):
    written = _write_member(tmp_path / member, header, trials, rows, style, derivatives)
    table = reader.read_table(tmp_path / member)
    named = header.lstrip("%").split()
    expect = ["trial", "t"] + named + ([f"d{name}/dt" for name in named] if derivatives else [])
    assert table.names == expect
    np.testing.assert_allclose(table.values, written, rtol=1e-15, atol=0)   # 17 digits: the bytes' numbers
    assert bool(table.notes) == derivatives
    if derivatives:
        assert len(table.notes) == 1 and "d/dt of each" in table.notes[0] and "--dxdt" in table.notes[0]
        # the trailing columns are d/dt of the named ones in order: the finite difference of each agrees
        first = table.values[:, 0] == 0
        t = table.column("t", "--time")[first]
        for name in named:
            dq = np.gradient(table.column(name, "--q")[first], t, edge_order=2)
            np.testing.assert_allclose(dq, table.column(f"d{name}/dt", "--dxdt")[first], atol=1e-3)


def test_a_member_with_derivative_columns_trains_and_its_own_derivatives_can_be_named(tmp_path, capsys):
    _write_member(tmp_path / "pendulum_h_1.txt", "% o v", 1, 493, "sci", True)
    train = hnn.load_task("measured", "train")
    argv = ["--data", str(tmp_path / "pendulum_h_1.txt"), "--time", "t", "--q", "o", "--v", "v", "--trial", "trial",
            "--model", "baseline", "--total_steps", "2", "--save_dir", str(tmp_path / "runs")]
    run = train.main(argv)
    assert (Path(run) / "scale.json").is_file()
    notes = [line for line in capsys.readouterr().out.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "do/dt, dv/dt" in notes[0]
    own = data.get_dataset(tmp_path / "pendulum_h_1.txt", q="o", v="v", trial="trial", dxdt="do/dt,dv/dt")
    differenced = data.get_dataset(tmp_path / "pendulum_h_1.txt", q="o", v="v", trial="trial")
    np.testing.assert_allclose(own["dxdt"], differenced["dxdt"], atol=1e-3)


@pytest.mark.parametrize("header, cells", [("% x v", 7), ("% x v", 3), ("t,x,v", 5), ("% trial t x", 4)])
def test_any_other_count_of_cells_is_refused_with_the_header_to_write_which_then_reads(tmp_path, header, cells):
    sep = "," if "," in header else " "
    rows = [sep.join(repr(0.1 * i + j) for j in range(cells)) for i in range(6)]
    path = tmp_path / "odd.txt"
    path.write_text("\n".join([header] + rows) + "\n")
    with pytest.raises(ValueError) as err:
        reader.read_table(path)
    message = str(err.value)
    assert "\n" not in message and f"line 2: {cells} cells" in message
    proposed = re.search(r"e\.g\. '([^']*)'$", message).group(1)
    path.write_text("\n".join([proposed] + rows) + "\n")
    table = reader.read_table(path)
    assert len(table.names) == cells and table.values.shape == (6, cells)


def _rotor(tmp_path: Path, name: str, turns: float) -> Path:
    """A driven arm turning ``turns`` times one way with a wobble, its angle logged unwrapped, and a spring."""
    t = np.linspace(0, 10, 500)
    theta = 2 * math.pi * turns * t / 10 + 0.3 * np.sin(3 * t)
    omega = 2 * math.pi * turns / 10 + 0.9 * np.cos(3 * t)
    x, v = 80 * np.cos(4 * t), -320 * np.sin(4 * t)            # a spring in pixels: wide, but it comes back
    cols = {"t": t, "o": theta, "w": omega, "x": x, "v": v}
    path = tmp_path / name
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(repr(float(c[i])) for c in cols.values())
                                                       for i in range(len(t))) + "\n")
    return path


def test_an_unwrapped_angle_read_as_a_position_gets_one_line_suggesting_periodic(tmp_path):
    path = _rotor(tmp_path, "rotor.csv", turns=6)
    rec = data.load(path, q="o,x", v="w,v")
    assert len(rec.notes) == 1 and "'o'" in rec.notes[0] and "--periodic o" in rec.notes[0]
    assert "6.0 turns" in rec.notes[0] and "\n" not in rec.notes[0]
    assert data.load(path, q="o,x", v="w,v", periodic="o").notes == []     # marked: no hint
    assert data.load(path, q="x", v="v").notes == []                       # the spring spans 25 turns' width
    assert data.load(_rotor(tmp_path, "swing.csv", turns=1), q="o", v="w").notes == []   # one turn: no hint


def test_the_scene_study_prints_the_hint_before_anything_else(tmp_path):
    path = _rotor(tmp_path, "rotor.csv", turns=6)
    done = subprocess.run([sys.executable, "analysis/scene_study.py", "--data", str(path), "--q", "o", "--v", "w",
                           "--horizon", "100"], cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})
    # refused for its horizon before any training, after the note
    assert done.returncode == 2 and "too short for --horizon 100" in done.stderr, done.stderr
    assert [line for line in done.stdout.splitlines() if "--periodic o" in line][0].startswith("note: ")


@pytest.mark.parametrize("energy", [False, True])
def test_the_card_carries_the_notes_its_naive_row_sits_in_its_table_and_its_stamp_says_file(tmp_path, energy):
    row = {"kind": "hnn", "hidden_dim": 32, "train_fraction": 1.0, "params": 1000, "test_loss": 0.1,
           "prediction_error": {"median": 1.0, "mean": 2.0}, "valid_time": {"median": 3.0}, "train_seconds": 1.0,
           "rollout_seconds": 0.1, "run": "runs/r", **({"energy_drift": {"model": 0.1, "measured": 0.2}} if energy else {})}
    meta = {"quick": False, "command": "python analysis/scene_study.py", "date": "d", "commit": "c", "torch": "t",
            "cores": 2, "jobs": 1, "horizon": 0.5, "units": "units of o", "notes": ["a hint about 'o'"]}
    text = measured_study.markdown({"scene": "s", "meta": meta, "rows": [row], "naive": {"median": 4.0, "mean": 5.0,
                                    "starts": 10}, "card": ["said"], "seconds": {"training": 1, "measure": 1, "total": 2}})
    assert "Note: a hint about 'o'." in text
    table = text[text.index("| model |"):].strip().splitlines()
    assert table[-1].startswith("| naive") and len({line.count("|") for line in table}) == 1, table
    outside = tmp_path / "m.csv"
    outside.write_text("t\n")
    assert measured_study._portable(str(outside)) == "FILE" and measured_study._portable(str(tmp_path)) == "DIR"
