"""Task 3, the real pendulum: finding and parsing the measurements, the dataset, the physics in it, training."""
import hashlib
import json
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

import hnn

HEADER = "%o v\r\n"


@pytest.fixture
def real():
    return hnn.load_task("real")


@pytest.fixture
def shipped(real):
    """The copy of the measurements that ships with the task."""
    return Path(real.__file__).parent / real.DATA_FILE


def make_zip(path, data_bytes, member):
    """``invar_datasets.zip`` at ``path`` holding ``data_bytes`` as ``member`` (and a decoy member)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr(str(Path(member).parent / "pendulum_h_1.txt").lstrip("./"), "% o v\r\n")
        archive.writestr(member, data_bytes)
    return path


def row(trial, t, theta, omega):
    return f"  {trial:.16e}  {t:.16e}  {theta:.16e}  {omega:.16e} \r\n"


def write(path, text):
    path.write_bytes(text.encode("ascii"))
    return path


def good_rows(n=6):
    return [row(0, 5 + i / 6, 0.1 * i, -0.2 * i) for i in range(n)]


# ---------------------------------------------------------------------------- finding the file

def test_default_is_the_shipped_copy_with_the_published_checksum(real, shipped, monkeypatch):
    monkeypatch.delenv("HNN_DATA_DIR", raising=False)
    assert real.find_data() == shipped
    assert hashlib.sha256(shipped.read_bytes()).hexdigest() == real.SHA256
    assert shipped.stat().st_size == 57274 and shipped.read_bytes().count(b"\r\n") == 557   # CRLF kept


def test_finds_the_text_file_through_the_env_var(real, shipped, tmp_path, monkeypatch):
    shutil.copy(shipped, tmp_path / real.DATA_FILE)
    monkeypatch.setenv("HNN_DATA_DIR", str(tmp_path))
    assert real.find_data() == tmp_path / real.DATA_FILE


def test_text_file_and_zip_give_identical_arrays(real, shipped, tmp_path):
    make_zip(tmp_path / real.ZIP_FILE, shipped.read_bytes(), real.DATA_FILE)
    assert real.find_data(tmp_path) == tmp_path / real.ZIP_FILE
    t_zip, x_zip = real.load_measurements(tmp_path)
    t_txt, x_txt = real.load_measurements()
    assert t_txt.shape == (556,) and x_txt.shape == (556, 2)
    assert t_txt.dtype == x_txt.dtype == np.float64
    np.testing.assert_array_equal(t_zip, t_txt)
    np.testing.assert_array_equal(x_zip, x_txt)
    assert t_txt[0] == 5.0 and t_txt[-1] == 99.5


def test_text_file_wins_over_the_zip_and_data_dir_wins_over_the_env_var(real, shipped, tmp_path, monkeypatch):
    make_zip(tmp_path / real.ZIP_FILE, shipped.read_bytes(), real.DATA_FILE)
    shutil.copy(shipped, tmp_path / real.DATA_FILE)
    monkeypatch.setenv("HNN_DATA_DIR", str(tmp_path / "elsewhere"))
    assert real.find_data(tmp_path) == tmp_path / real.DATA_FILE
    assert real.find_data(str(tmp_path)) == tmp_path / real.DATA_FILE


def test_zip_with_the_member_in_a_subfolder(real, shipped, tmp_path):
    make_zip(tmp_path / real.ZIP_FILE, shipped.read_bytes(), f"invar_datasets/{real.DATA_FILE}")
    t, x = real.load_measurements(tmp_path)
    t_txt, x_txt = real.load_measurements()
    np.testing.assert_array_equal(t, t_txt)
    np.testing.assert_array_equal(x, x_txt)


@pytest.mark.parametrize("change", ["one digit", "LF line endings", "last row dropped"])
def test_a_changed_copy_fails_the_checksum(real, shipped, tmp_path, change):
    data = shipped.read_bytes()
    if change == "one digit":
        data = data.replace(b"e-001", b"e-002", 1)
    elif change == "LF line endings":
        data = data.replace(b"\r\n", b"\n")
    else:
        data = data[:data.rstrip().rfind(b"\r\n") + 2]
    (tmp_path / real.DATA_FILE).write_bytes(data)
    with pytest.raises(ValueError, match=rf"SHA-256 [0-9a-f]{{64}} is not the published file's {real.SHA256}"):
        real.load_measurements(tmp_path)
    t, _ = real.load_measurements(tmp_path, verify=False)          # parses; only the bytes differ
    assert len(t) == (555 if change == "last row dropped" else 556)


def test_missing_file_says_where_it_looked_and_how_to_point_at_it(real, tmp_path, monkeypatch):
    for match in ("HNN_DATA_DIR=DIR", "--data_dir DIR", "Schmidt", "Science 324:81", "invar_datasets",
                  re.escape(str(tmp_path))):
        with pytest.raises(FileNotFoundError, match=match):
            real.find_data(tmp_path)
    monkeypatch.setenv("HNN_DATA_DIR", str(tmp_path / "nowhere"))
    with pytest.raises(FileNotFoundError, match=r"from HNN_DATA_DIR.*does not exist"):
        real.get_dataset()


def test_zip_without_the_member_is_not_found(real, tmp_path):
    with zipfile.ZipFile(tmp_path / real.ZIP_FILE, "w") as archive:
        archive.writestr("pendulum_h_1.txt", "% o v\r\n")
    with pytest.raises(FileNotFoundError, match=f"holds no {real.DATA_FILE}"):
        real.find_data(tmp_path)


# ---------------------------------------------------------------------------- malformed files

@pytest.mark.parametrize("lines, match", [
    ([HEADER] + good_rows(3) + ["  0.0  5.6  abc  0.1 \r\n"] + good_rows(2),
     r"line 5: the theta value 'abc' is not a number"),
    ([HEADER] + good_rows(2) + ["  0.0  5.6  0.1 \r\n"] + good_rows(2), r"line 4: 3 columns, expected 4"),
    ([HEADER] + good_rows(4) + ["  0.0  5.9  nan  0.1 \r\n"], r"line 6: the theta value is nan"),
    ([HEADER] + [row(0, 5.0, 0, 0), row(0, 5.5, 0, 0), row(0, 5.5, 0, 0)], r"line 4: time 5.5 does not increase"),
    ([HEADER] + [row(0, 5.0, 0, 0), row(1, 5.5, 0, 0)], r"line 3: trial 1 follows trial 0"),
    ([], r"line 1: the file is empty"),
    (["\r\n", "  \r\n"], r"line 1: the file is empty"),
    ([HEADER], r"line 1: 0 data rows"),
    (good_rows(4), r"line 1: expected the header '%o v'"),
])
def test_malformed_file_names_the_line(real, tmp_path, lines, match):
    path = write(tmp_path / real.DATA_FILE, "".join(lines))
    with pytest.raises(ValueError, match=match) as err:
        real.load_measurements(tmp_path, verify=False)
    assert str(path) in str(err.value)


def test_good_small_file_parses_with_lf_or_crlf(real, tmp_path):
    text = HEADER + "".join(good_rows(5))
    for name, body in (("crlf", text), ("lf", text.replace("\r\n", "\n"))):
        (tmp_path / name).mkdir()
        write(tmp_path / name / real.DATA_FILE, body)
        t, x = real.load_measurements(tmp_path / name, verify=False)
        np.testing.assert_allclose(t, 5 + np.arange(5) / 6)
        np.testing.assert_allclose(x, np.stack([0.1 * np.arange(5), -0.2 * np.arange(5)], 1))


def test_malformed_zip_member_names_archive_and_line(real, tmp_path):
    with zipfile.ZipFile(tmp_path / real.ZIP_FILE, "w") as archive:
        archive.writestr(real.DATA_FILE, HEADER + "".join(good_rows(3)) + "  0.0  5.6  abc  0.1 \r\n")
    with pytest.raises(ValueError, match=rf"invar_datasets.zip:{real.DATA_FILE}: line 5"):
        real.load_measurements(tmp_path, verify=False)


# ---------------------------------------------------------------------------- the dataset

def test_shapes_dtypes_and_the_ordered_split(real):
    d = real.get_dataset()
    for key, rows in (("x", 445), ("dxdt", 445), ("test_x", 110), ("test_dxdt", 110)):
        assert d[key].shape == (rows, 2) and d[key].dtype == np.float32, key
    assert d["t"].shape == (445,) and d["test_t"].shape == (110,)
    assert d["t"].dtype == d["test_t"].dtype == np.float64
    assert d["dt"] == pytest.approx(1 / 6)
    assert d["test_t"][0] == pytest.approx(81.0) and d["test_t"][-1] == pytest.approx(99.0 + 1 / 6)
    t, x = real.load_measurements()
    # train = rows 0:444 and the leftover row 554, which comes after the test block (rows 444:554)
    np.testing.assert_array_equal(d["t"], np.concatenate([t[:444], t[554:555]]))
    np.testing.assert_array_equal(d["test_t"], t[444:554])
    assert d["t"][443] < d["test_t"][0] and d["t"][-1] > d["test_t"][-1]
    np.testing.assert_array_equal(d["x"][-1], x[554].astype(np.float32))
    np.testing.assert_array_equal(d["test_x"], x[444:554].astype(np.float32))


def test_derivatives_are_forward_differences_over_the_actual_steps(real):
    d = real.get_dataset()
    t, x = real.load_measurements()
    steps = np.diff(t)
    gaps = np.flatnonzero(steps > 0.2)
    assert len(gaps) == 10                                   # 8 steps of 1/3 s, 2 of 1/2 s
    np.testing.assert_allclose(np.sort(steps[gaps]), [1 / 3] * 8 + [1 / 2] * 2)
    forward = np.array([(x[i + 1] - x[i]) / (t[i + 1] - t[i]) for i in range(555)])
    both = np.concatenate([d["dxdt"], d["test_dxdt"]])
    order = np.concatenate([np.arange(444), [554], np.arange(444, 554)])
    np.testing.assert_allclose(both, forward[order].astype(np.float32), rtol=1e-6, atol=1e-6)
    # across a gap the step is the real one, not the nominal 1/6 s
    g = gaps[0]
    assert g < 444
    np.testing.assert_allclose(d["dxdt"][g], (x[g + 1] - x[g]) / steps[g], rtol=1e-6)
    assert not np.allclose(d["dxdt"][g], (x[g + 1] - x[g]) * 6, rtol=1e-3)


def test_the_measurements_are_a_pendulum(real):
    """Independent of the loader's differencing: theta'' ~ -k sin(theta), theta' ~ omega."""
    t, x = real.load_measurements()
    theta, omega = x[:, 0], x[:, 1]
    h = np.diff(t)
    alpha = np.diff(omega) / h
    s = np.sin(theta[:-1])
    k = -(alpha @ s) / (s @ s)                               # least squares alpha = -k sin(theta)
    assert 1.1 < k < 1.45
    residual = alpha + k * s
    assert residual.std() < 0.25 * alpha.std()               # the sine law explains most of alpha
    velocity = np.diff(theta) / h
    assert np.corrcoef(velocity, omega[:-1])[0, 1] > 0.99
    assert np.abs(theta).max() < 1.6 and np.abs(omega).max() < 1.6


def test_hamiltonian_is_the_papers_fitted_energy(real):
    x = torch.tensor([[0.0, 0.0], [np.pi, 0.0], [0.0, 1.5], [1.0, -0.5]], dtype=torch.float64)
    expected = 2.4 * (1 - np.cos(x[:, 0].numpy())) + x[:, 1].numpy() ** 2
    H = real.hamiltonian(x)
    assert H.shape == (4,)
    np.testing.assert_allclose(H.numpy(), expected)
    np.testing.assert_allclose(real.hamiltonian(x.numpy()), expected)


# ---------------------------------------------------------------------------- training

@pytest.mark.parametrize("extra", [[], ["--baseline"], ["--use_rk4"]])
def test_train_script_end_to_end(extra, tmp_path, capsys):
    trainer = hnn.load_task("real", "train")
    run = trainer.main(["--total_steps", "5", "--print_every", "2", "--verbose", "--save_dir", str(tmp_path)] + extra)
    out = capsys.readouterr().out
    assert "step 4, train_loss" in out and "Final train loss" in out and "Final test loss" in out
    label = "baseline" if "--baseline" in extra else "hnn-rk4" if "--use_rk4" in extra else "hnn"
    assert run.parent == tmp_path and run.name.startswith(f"real-{label}-seed0-")
    args = json.loads((run / "args.json").read_text())
    metrics = json.loads((run / "metrics.json").read_text())
    assert args["weight_decay"] == 1e-5 and args["batch_size"] is None and args["data_dir"] is None
    assert args["name"] == "real" and args["input_dim"] == 2
    assert len(metrics["history"]["train_loss"]) == 6 and metrics["test_loss"] > 0
    model, saved_args, _ = hnn.load_run(run)
    assert saved_args == args and model.baseline == ("--baseline" in extra)


def test_train_script_data_dir_flag(real, shipped, tmp_path, monkeypatch):
    trainer = hnn.load_task("real", "train")
    monkeypatch.setenv("HNN_DATA_DIR", str(tmp_path / "nowhere"))
    argv = ["--total_steps", "1", "--save_dir", str(tmp_path / "runs")]
    with pytest.raises(FileNotFoundError, match="HNN_DATA_DIR"):
        trainer.main(argv)
    make_zip(tmp_path / real.ZIP_FILE, shipped.read_bytes(), real.DATA_FILE)
    run = trainer.main(argv + ["--data_dir", str(tmp_path)])
    assert json.loads((run / "args.json").read_text())["data_dir"] == str(tmp_path)
