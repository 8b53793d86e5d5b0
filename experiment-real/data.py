"""Task 3, the real pendulum: measurements of a real, slightly damped pendulum (Schmidt & Lipson 2009).

One trajectory of 556 samples (t from 5.0 to 99.5 s, nominal step 1/6 s with 10 larger gaps)
of the angle theta and the angular velocity omega, from the supplementary data
("invar_datasets") of M. Schmidt and H. Lipson, "Distilling Free-Form Natural Laws from
Experimental Data", Science 324(5923):81-85, 2009. The inputs are x = (theta, omega); the
targets are forward finite differences of x over the actual time steps. The first ~4/5 of the
trajectory trains, the rest tests.

The measurements ship beside this file (``real_pend_h_1.txt``; its provenance, citation and
checksum are in ``DATA.md`` here). Another copy, the text file or the authors' archive
``invar_datasets.zip`` holding it, is read from ``--data_dir DIR`` or ``HNN_DATA_DIR=DIR``.
Every copy is checked against the published file's SHA-256 after parsing.
"""
from __future__ import annotations

import hashlib
import math
import os
import zipfile
from pathlib import Path, PurePosixPath

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
DATA_FILE = "real_pend_h_1.txt"
ZIP_FILE = "invar_datasets.zip"
ENV_VAR = "HNN_DATA_DIR"
NOMINAL_DT = 1.0 / 6.0      # the sampling step of the measurements (the original's dt for --use_rk4)
HEADER = ("o", "v")          # the file's header names its two state columns: o = theta, v = omega
NUM_COLUMNS = 4              # trial, t, theta, omega
# SHA-256 of the published file (the zip member is the same bytes); see DATA.md
SHA256 = "45d92988198b89a5933f5a53e67aa819d06937516f71a462ac09e1307d8b3411"

SOURCE = ('the supplementary data "invar_datasets" of M. Schmidt and H. Lipson, "Distilling Free-Form '
          'Natural Laws from Experimental Data", Science 324:81 (2009)')


def hamiltonian(x):
    """The paper's fitted "energy" 2.4 (1 - cos q) + p^2 of states ``x = [q, p]`` ``(batch, 2)`` -> ``(batch,)``.

    Only the energy function of the energy metric (k = 2.4 was fit to the data by the paper's
    authors): the measured pendulum has friction, so the data do not conserve it.
    """
    q, p = x[..., 0], x[..., 1]
    cos = torch.cos(q) if torch.is_tensor(q) else np.cos(q)
    return 2.4 * (1 - cos) + p ** 2


# ----------------------------------------------------------------------------------------------
# finding the file


def _default_dir() -> tuple[Path, str]:
    """The folder to search when no ``data_dir`` is given, and where that choice came from."""
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return Path(env).expanduser(), f"from {ENV_VAR}"
    return HERE, "the copy shipped with the task; neither --data_dir nor HNN_DATA_DIR was given"


def _zip_member(archive: zipfile.ZipFile) -> str | None:
    """The name of ``DATA_FILE`` in the archive: at its root, or else in one subfolder level."""
    names = [n for n in archive.namelist() if not n.endswith("/")]
    if DATA_FILE in names:
        return DATA_FILE
    nested = sorted(n for n in names
                    if PurePosixPath(n).name == DATA_FILE and len(PurePosixPath(n).parts) == 2)
    return nested[0] if nested else None


def find_data(data_dir=None) -> Path:
    """The measurements file: ``real_pend_h_1.txt``, or else ``invar_datasets.zip`` holding it.

    Searches ``data_dir`` if given, else the folder in the environment variable ``HNN_DATA_DIR``,
    else this task's folder (the shipped copy). ``data_dir`` may also name one of the two files itself. Raises
    ``FileNotFoundError`` saying where it looked and where the data come from.
    """
    if data_dir is not None and str(data_dir).strip():
        folder, origin = Path(data_dir).expanduser(), "from --data_dir"
    else:
        folder, origin = _default_dir()
    notes = []
    if folder.is_file() and folder.name in (DATA_FILE, ZIP_FILE):       # pointed at the file itself
        folder, candidates = folder.parent, [folder]
    else:
        candidates = [folder / DATA_FILE, folder / ZIP_FILE]
        if not folder.is_dir():
            notes.append(f"the folder {folder} does not exist")
    for path in candidates:
        if not path.is_file():
            continue
        if path.name == DATA_FILE:
            return path
        try:
            with zipfile.ZipFile(path) as archive:
                if _zip_member(archive) is not None:
                    return path
            notes.append(f"{path} holds no {DATA_FILE} (at its root or one folder down)")
        except (zipfile.BadZipFile, OSError) as err:
            notes.append(f"{path} is not a readable zip archive ({err})")
    detail = "".join(f"; {n}" for n in notes)
    raise FileNotFoundError(
        f"the real-pendulum measurements {DATA_FILE} were not found: searched the folder {folder} "
        f"({origin}) for {DATA_FILE} or {ZIP_FILE} containing it{detail}. "
        f"The data come from {SOURCE}, in the supplementary archive {ZIP_FILE}, and a copy ships as "
        f"experiment-real/{DATA_FILE}: restore it (git checkout -- experiment-real/{DATA_FILE}), or put "
        f"{DATA_FILE} or {ZIP_FILE} in a folder and point at it with --data_dir DIR or {ENV_VAR}=DIR.")


# ----------------------------------------------------------------------------------------------
# reading it


def _read_text(path: Path) -> tuple[bytes, str]:
    """The file's bytes and the name to quote in errors (``archive.zip:member`` for a zip member)."""
    if path.suffix == ".zip":
        try:
            with zipfile.ZipFile(path) as archive:
                member = _zip_member(archive)
                if member is None:
                    raise FileNotFoundError(f"{path} holds no {DATA_FILE} (at its root or one folder down)")
                raw, label = archive.read(member), f"{path}:{member}"
        except zipfile.BadZipFile as err:
            raise ValueError(f"{path} is not a readable zip archive ({err})") from err
    else:
        raw, label = path.read_bytes(), str(path)
    return raw, label


def _decode(raw: bytes, label: str) -> str:
    try:
        return raw.decode("ascii")
    except UnicodeDecodeError as err:
        raise ValueError(f"{label}: not an ASCII text file ({err}); expected the {DATA_FILE} "
                         f"table of {SOURCE}") from None


def _check_sha256(raw: bytes, label: str) -> None:
    """Well-formed but not the published bytes: a truncated, edited or re-encoded copy."""
    digest = hashlib.sha256(raw).hexdigest()
    if digest != SHA256:
        raise ValueError(
            f"{label}: SHA-256 {digest} is not the published file's {SHA256}, so it is a changed copy "
            f"(edited, truncated or with converted line endings) of {SOURCE}. Restore the shipped copy "
            f"(git checkout -- experiment-real/{DATA_FILE}) or point --data_dir at an unchanged one; to "
            "read other measurements in the same format on purpose, call load_measurements(..., verify=False).")


def _parse(text: str, label: str) -> tuple[np.ndarray, np.ndarray]:
    """``(t, x)`` from the file's text; every malformed line is a ``ValueError`` naming its number."""
    lines = text.split("\n")        # CRLF or LF; a trailing CR is whitespace, stripped below
    numbered = [(i + 1, line.strip()) for i, line in enumerate(lines) if line.strip()]
    if not numbered:
        raise ValueError(f"{label}: line 1: the file is empty; expected the header '%o v' and then rows "
                         f"of {NUM_COLUMNS} numbers (trial, t, theta, omega)")
    first_no, header = numbered[0]
    names = tuple(header.lstrip("%").split())
    if not header.startswith("%") or names != HEADER:
        raise ValueError(f"{label}: line {first_no}: expected the header '%o v' (the columns trial, t, "
                         f"o = theta, v = omega), found {header[:60]!r}")
    rows = []
    for number, line in numbered[1:]:
        fields = line.split()
        if len(fields) != NUM_COLUMNS:
            raise ValueError(f"{label}: line {number}: {len(fields)} columns, expected {NUM_COLUMNS} "
                             f"(trial, t, theta, omega): {line[:80]!r}")
        values = []
        for column, field in zip(("trial", "t", "theta", "omega"), fields):
            try:
                value = float(field)
            except ValueError:
                raise ValueError(f"{label}: line {number}: the {column} value {field!r} is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"{label}: line {number}: the {column} value is {field} (NaN/inf)")
            values.append(value)
        if rows:
            if values[0] != rows[-1][0]:
                raise ValueError(f"{label}: line {number}: trial {values[0]:g} follows trial {rows[-1][0]:g}; "
                                 "expected one trajectory (a single trial)")
            if not values[1] > rows[-1][1]:
                raise ValueError(f"{label}: line {number}: time {values[1]!r} does not increase "
                                 f"(the previous row has t = {rows[-1][1]!r})")
        rows.append(values)
    if len(rows) < 2:
        raise ValueError(f"{label}: line {first_no}: {len(rows)} data rows after the header; "
                         "expected a trajectory of at least 2 rows")
    table = np.array(rows, dtype=np.float64)
    return table[:, 1].copy(), table[:, 2:4].copy()


def load_measurements(data_dir=None, verify: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The measured trajectory: times ``t`` ``(N,)`` in seconds and states ``x`` ``(N, 2)`` = (theta, omega).

    Both float64. Reads ``real_pend_h_1.txt`` or its copy inside ``invar_datasets.zip``
    (see ``find_data``); a malformed file raises ``ValueError`` naming the file and the line,
    and (with ``verify``) a well-formed file whose SHA-256 is not the published one raises too.
    """
    raw, label = _read_text(find_data(data_dir))
    parsed = _parse(_decode(raw, label), label)
    if verify:
        _check_sha256(raw, label)
    return parsed


SPLITS = ("original", "dhnn")


def _dhnn_dataset(t: np.ndarray, x: np.ndarray, train_fraction: float) -> dict:
    """The D-HNN paper's rows of the measurements ``t`` ``(N,)``, ``x`` ``(N, 2)`` (see ``get_dataset``)."""
    forward = (x[1:] - x[:-1]) / (t[1:] - t[:-1])[:, None]
    dxdt = forward.copy()
    dxdt[:-1] = (forward[:-1] + forward[1:]) / 2     # centred on x[i + 1]: the mean of its two one-sided slopes
    x, t = x[1:], t[1:]
    a = int((len(x) + 1) * train_fraction)   # their split counts the file's rows, N = 556
    data = {"dt": NOMINAL_DT}
    for key, arr, dtype in (("x", x, np.float32), ("dxdt", dxdt, np.float32), ("t", t, np.float64)):
        data[key], data["test_" + key] = arr[:a].astype(dtype), arr[a:].astype(dtype)
    return data


def get_dataset(data_dir=None, test_split: float = 0.8, verify: bool = True, split: str = "original") -> dict:
    """The original's dataset: inputs x = (theta, omega), targets their forward differences.

    dx[i] = (x[i+1] - x[i]) / (t[i+1] - t[i]) over the actual time steps (1/6 s, or 1/3 s and
    1/2 s across the 10 gaps) and x = x[:-1]: 555 rows. The split keeps the order, as the
    original: ``test_split`` is the train fraction, train_size = int(555 * 0.8) = 444 and
    test_size = int(555 * (1 - 0.8)) = 110 (float truncation of 110.99...). Test = rows 444:554
    (t from 81.0 to 99.17 s); train = rows 0:444 plus the leftover row 554: 445 rows.

    Returns float32 ``x``, ``dxdt`` (445, 2) and ``test_x``, ``test_dxdt`` (110, 2); float64
    ``t`` (445,) and ``test_t`` (110,), the times of those rows; and ``dt`` = 1/6, the nominal
    step (used by ``--use_rk4``).

    ``split='dhnn'`` is the D-HNN paper's preparation of the same file instead (Sosanya &
    Greydanus 2022, as their code does it): targets are central differences, the mean of the
    forward differences on either side of each row (the last row keeps its backward one), on
    the rows after the first (555 rows), and the first int(556 * 0.8) = 444 of them train, the
    other 111 test, in time order (no leftover row).
    """
    if not 0.0 < test_split < 1.0:
        raise ValueError(f"test_split is the train fraction and must lie in (0, 1), got {test_split}")
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; use one of {', '.join(SPLITS)}")
    t, x = load_measurements(data_dir, verify)
    if split == "dhnn":
        return _dhnn_dataset(t, x, test_split)
    dxdt = (x[1:] - x[:-1]) / (t[1:] - t[:-1])[:, None]
    x, t = x[:-1], t[:-1]
    n = len(x)
    train_size, test_size = int(n * test_split), int(n * (1 - test_split))
    a, b = train_size, train_size + test_size

    def split(arr):
        return np.concatenate([arr[:a], arr[b:]]), arr[a:b]

    data = {"dt": NOMINAL_DT}
    for key, arr, dtype in (("x", x, np.float32), ("dxdt", dxdt, np.float32), ("t", t, np.float64)):
        data[key], data["test_" + key] = (part.astype(dtype) for part in split(arr))
    return data
