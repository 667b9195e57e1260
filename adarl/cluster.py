"""Connecting to Ray: a local instance or a cluster, with a one-line error when it cannot be
reached. Shared by sweeps (`adarl.sweeps.backends`) and suite evaluation
(`adarl.evaluation.parallel`), so it sits below both."""

from __future__ import annotations

import os
import socket

from adarl.errors import UsageError

RAY_INSTALL = "pip install 'adarl[ray]'"


def connect_ray(address: str | None, cpus: int):
    """`ray.init` on the cluster at `address` (checked to answer first), or on a local instance
    with `cpus` CPUs; returns the `ray` module. Any failure is a one-line `UsageError`."""
    ray = import_ray()
    if address:
        check_reachable(address)
    try:
        if address:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    except (ConnectionError, OSError, RuntimeError, ValueError, ray.exceptions.RayError) as exc:
        ray.shutdown()
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        raise UsageError(f"cannot start or reach {where}: {message}") from None
    return ray


def import_ray():
    try:
        import ray
    except ImportError:
        raise UsageError(
            f"--backend ray needs Ray, which is not installed; install it with: {RAY_INSTALL}"
        ) from None
    return ray


CONNECT_TIMEOUT_S = 5.0  # for the TCP connection and for the first HTTP/2 frame
# An HTTP/2 client's connection preface and an empty SETTINGS frame: every gRPC server (Ray's GCS,
# its client server) answers with a SETTINGS frame of its own.
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


def check_reachable(address: str, timeout_s: float | None = None) -> None:
    """A one-line UsageError unless a gRPC server answers at a Ray address within `timeout_s`
    (default CONNECT_TIMEOUT_S): ray.init would otherwise wait minutes on a host that drops
    packets or a port that accepts and never answers. `auto` is left to Ray, which fails fast
    when it finds no cluster."""
    if address == "auto":
        return
    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise UsageError(f"Ray address {address!r} is not HOST:PORT, ray://HOST:PORT or auto")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s) as conn:
            if os.environ.get("RAY_USE_TLS", "0").lower() in ("0", "false", ""):
                conn.sendall(_HTTP2_PREFACE)
                frame = _read_exactly(conn, 9)
                if len(frame) < 9 or frame[3] != 4:  # frame type 4: SETTINGS
                    raise UsageError(
                        f"the Ray cluster at {address} does not answer: something listens "
                        f"there but it is not a Ray head node (no gRPC reply)"
                    )
    except TimeoutError:
        raise UsageError(
            f"the Ray cluster at {address} does not answer (no reply in {timeout_s:g} s)"
        ) from None
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise UsageError(f"cannot reach the Ray cluster at {address}: {reason}") from None


def _read_exactly(conn: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data
