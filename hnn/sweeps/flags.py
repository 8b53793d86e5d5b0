"""The flags of a sweep's command: ``--device``, ``--backend``, ``--ray-address`` and ``--group``, added to an
analysis command's parser and checked there, then passed to ``hnn.sweeps.sweep.train_jobs``.

    flags.add_backend_flags(parser)
    args = parser.parse_args(argv)
    flags.check_backend(parser, args)
    sweep.train_jobs(jobs, args.jobs, out / "logs", args.backend, args.ray_address, args.group, args.device)
"""
from __future__ import annotations

from .. import names, settings

# torch-free: a command's parser takes these flags before torch loads (its input errors answer at once);
# check_backend imports the backends, and Ray, only when asked for it


def add_device_flag(parser) -> None:
    """Add ``--device`` (every run's torch device) to an analysis command's ``parser``."""
    parser.add_argument("--device", type=settings.device, default=None,
                        help="torch device every run trains on (cpu, cuda, cuda:1); default: each run's own, the "
                             "cpu. Not part of a run's identity: a run saved on one device is reused on another")


def add_backend_flags(parser) -> None:
    """Add ``--backend {local,ray}``, ``--ray-address ADDR``, ``--group`` and ``--device`` to a sweep's
    ``parser``; check them with ``check_backend`` and pass them to ``train_jobs``."""
    add_device_flag(parser)
    parser.add_argument("--backend", choices=names.BACKENDS, default="local",
                        help="where the runs train: local = in this process (--jobs 1) or in --jobs N worker "
                             "processes here; ray = one Ray task per run with cores // --jobs threads, as many at "
                             "once as Ray has CPUs (needs the ray extra); see docs/sweeps.md")
    parser.add_argument("--ray-address", dest="ray_address", default=None, metavar="ADDR",
                        help="with --backend ray: the Ray cluster to join (its head's address, e.g. 10.0.0.1:6379, "
                             "or auto); default: start a local Ray with this machine's cores. --out must be on "
                             "storage every node sees at the same path")


    parser.add_argument("--group", choices=names.GROUP_MODES, default="auto",
                        help="auto: train the runs that can share one program (one task, kind and width, seeds "
                             "and data fractions apart) as batched groups, each run still saved as its own folder: "
                             "on the CPU the paper's tanh-MLP kinds up to a width of hnn.sweeps.sweep.GROUP_MAX_WIDTH, on "
                             "a GPU every kind; all: every kind on every device; off: every run alone")


def check_backend(parser, args) -> None:
    """Bad backend flags exit with one ``error:`` line (``parser.error``, code 2) naming the fix,
    among them ``--backend ray`` without Ray installed."""
    if args.ray_address is not None and args.backend != "ray":
        parser.error(f"--ray-address {args.ray_address}: only used with --backend ray; add --backend ray or drop it")
    if args.backend == "ray":
        from .backends import import_ray, probe
        try:
            import_ray()
            if args.ray_address is not None:
                probe(args.ray_address)
        except (ImportError, ConnectionError) as err:
            parser.error(str(err))
