"""The cluster options of ``mobisense sweep`` and ``mobisense solve --multistart``, validated before any work.

``--workers N`` local processes (N ≥ 1), or ``--scheduler ADDRESS`` of a running dask scheduler with dask's TLS
settings (``--tls-ca-file``, ``--tls-cert``, ``--tls-key``: :class:`distributed.security.Security` with
encryption required). dask exchanges pickled data, so a scheduler reached over plain ``tcp://`` on another
host can run code in the client: :func:`insecure_warning` says so once it has answered. Imports nothing heavy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...core.errors import ConfigError

__all__ = ["CONNECT_TIMEOUT", "MAX_COUNT", "Cluster", "add_cluster_arguments", "check_count", "insecure_warning",
           "positive_int"]  # fmt: skip

#: seconds to connect to a ``--scheduler`` before giving up (exit status 2)
CONNECT_TIMEOUT = 10.0
_LOOPBACK = ("localhost", "127.", "::1", "[::1]", "0.0.0.0")
#: most local worker processes (``--workers``) and multi-start starts (``--multistart``)
MAX_COUNT = 4096


def positive_int(text: str) -> int:
    """The argparse type of an integer >= 1 (``--workers``, ``--multistart``)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text[:40]!r}") from None
    if not 1 <= value <= MAX_COUNT:
        raise argparse.ArgumentTypeError(f"expected an integer in 1 … {MAX_COUNT}, got {value}")
    return value


def check_count(name: str, value: Any, caller: str) -> None:
    """Refuse a number of workers or starts given in Python that :func:`positive_int` would refuse on the command line.

    Raises
    ------
    TypeError
        ``value`` is not an integer (``caller: name: expected an integer in 1 … 4096, got float``).
    ConfigError
        ``value`` is outside 1 … :data:`MAX_COUNT`.
    """
    import numbers

    expected = f"expected an integer in 1 … {MAX_COUNT}"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{caller}: {name}: {expected}, got {type(value).__name__}")
    if not 1 <= value <= MAX_COUNT:
        raise ConfigError(f"{caller}: {name}: {expected}, got {value}")


def add_cluster_arguments(parser: Any, what: str) -> None:
    """``--workers``, ``--scheduler`` and dask's TLS settings (``--tls-ca-file``, ``--tls-cert``, ``--tls-key``)."""
    parser.add_argument("--workers", type=positive_int, default=None, help=f"local worker processes for {what} "
                        "(default: one per core)")  # fmt: skip
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help=f"address of a running dask scheduler for {what} (tls://host:port, tcp://…); dask "
                        "exchanges pickles: use tls:// and the --tls-* options on networks you do not own")  # fmt: skip
    parser.add_argument("--tls-ca-file", type=Path, default=None, help="CA certificate of the scheduler (PEM)")
    parser.add_argument("--tls-cert", type=Path, default=None, help="client certificate (PEM)")
    parser.add_argument("--tls-key", type=Path, default=None, help="client private key (PEM; default: in --tls-cert)")


@dataclass(frozen=True)
class Cluster:
    """Where tasks run: a ``scheduler`` address with dask ``security``, or ``workers`` local processes."""

    scheduler: str | None = None
    workers: int | None = None
    security: Any = None

    @classmethod
    def from_args(cls, args: Any) -> Cluster:
        """Validate the cluster options of a command before any work (``ConfigError``, one line; TLS warning)."""
        scheduler = args.scheduler
        files = {"--tls-ca-file": args.tls_ca_file, "--tls-cert": args.tls_cert, "--tls-key": args.tls_key}
        given = {k: v for k, v in files.items() if v is not None}
        for option, path in given.items():
            if not path.is_file():
                raise ConfigError(f"{option} {path}: file not found")
        if given and scheduler is None:
            raise ConfigError(f"{', '.join(given)}: only used with --scheduler")
        if scheduler is None:
            return cls(workers=args.workers)
        if args.workers is not None:
            raise ConfigError("--workers: local workers are not used with --scheduler (the cluster has its own)")
        scheme, sep, rest = scheduler.partition("://")
        if not rest.strip():
            raise ConfigError(f"--scheduler {scheduler[:80]!r}: expected the address of a dask scheduler "
                              "(tls://host:port), got none")  # fmt: skip
        if not sep:
            scheme, rest = ("tls" if given else "tcp"), scheduler
        if scheme not in ("tcp", "tls", "inproc", "ucx", "ws", "wss"):
            raise ConfigError(f"--scheduler {scheduler[:80]}: unknown protocol {scheme!r} (tls://host:port or tcp://…)")
        if given and scheme not in ("tls", "wss"):
            raise ConfigError(f"--scheduler {scheduler[:80]}: the --tls-* options need a tls:// address")
        security = None
        if given:
            from distributed.security import Security

            security = Security(
                tls_ca_file=str(args.tls_ca_file) if args.tls_ca_file else None,
                tls_client_cert=str(args.tls_cert) if args.tls_cert else None,
                tls_client_key=str(args.tls_key) if args.tls_key else None,
                require_encryption=True,
            )
        return cls(scheduler=f"{scheme}://{rest}", security=security)


def insecure_warning(address: str, security: Any = None) -> str | None:
    """The warning for a scheduler reached unencrypted on another host (None for tls://, loopback or TLS settings).

    Said once the scheduler has answered (:func:`mobisense.ocp.batch.engine.open_client`): an address that is
    refused gets its error alone.
    """
    scheme, _, rest = address.partition("://")
    host = rest.rsplit(":", 1)[0] if ":" in rest else rest
    if security is not None or scheme not in ("tcp", "ws") or host.startswith(_LOOPBACK):
        return None
    return (f"--scheduler {address[:80]} is not encrypted: dask exchanges pickled data, so whoever controls or "
            "intercepts that scheduler can run code in this process; use tls:// with --tls-ca-file/--tls-cert/"
            "--tls-key")  # fmt: skip
