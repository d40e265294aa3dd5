"""Sweeps on a real Dask cluster: a scheduler and two workers started from the venv
(``dask scheduler``, ``dask worker``) on 127.0.0.1, against the embedded default.

- the outage Monte Carlo and a fleet of five logs give the same results, bit for bit;
- a worker killed mid-sweep loses nothing;
- a scheduler reached over TLS with a self-signed certificate.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import operator
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest

from navreplay.pipeline.compute import ComputeParams, run_tasks
from navreplay.pipeline.outages.montecarlo import Case
from tests.pipeline.scenarios.drives import montecarlo_rows

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).parent / "dask"
DATA = REPO.parent / "shared" / "data"


def _start_cluster(tmp: Path, workers: int, tls: list[str] | None = None) -> tuple[str, list[Any]]:
    """A scheduler and ``workers`` single-threaded workers; (address, processes)."""
    sched_file = tmp / "scheduler.json"
    env = dict(os.environ, PYTHONPATH=str(REPO))  # the tests' own task functions import
    proto = ["--protocol", "tls"] if tls else []
    procs = [
        subprocess.Popen(
            [
                str(DASK),
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
                *proto,
                *(tls or []),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    deadline = time.monotonic() + 60
    while not sched_file.is_file() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert sched_file.is_file(), "the scheduler did not start"
    address = json.loads(sched_file.read_text())["address"]
    for i in range(workers):
        procs.append(
            subprocess.Popen(
                [
                    str(DASK),
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "1",
                    "--no-dashboard",
                    "--host",
                    "127.0.0.1",
                    "--name",
                    f"w{i}",
                    *(tls or []),
                ],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
    return address, procs


def _stop(procs: list[Any]) -> None:
    for p in reversed(procs):
        p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()


def _wait_for_workers(address: str, n: int, security: Any = None) -> None:
    from distributed import Client

    with Client(address, security=security, timeout="60s") as c:
        c.wait_for_workers(n, timeout=120)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    address, procs = _start_cluster(tmp_path_factory.mktemp("dask"), 2)
    try:
        _wait_for_workers(address, 2)
        yield address
    finally:
        _stop(procs)


def _without_timing(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k != "replay_s"} for r in rows]


DRIVE_S = 90.0  # the nominal run starts once the car has moved (heading from its motion)
STARTS = (30.0, 36.0, 42.0, 48.0, 54.0, 60.0)
CASES = (Case(10.0, 0), Case(10.0, 4))


def test_a_montecarlo_on_the_cluster_equals_the_embedded_default(cluster: str) -> None:
    # the embedded default first: it compiles (or loads) the kernel the workers then load
    local = montecarlo_rows("lc_ekf", DRIVE_S, STARTS, CASES, tail_s=5.0)
    remote = montecarlo_rows("lc_ekf", DRIVE_S, STARTS, CASES, tail_s=5.0, scheduler=cluster)
    assert len(local) == len(STARTS) * len(CASES)
    assert _without_timing(remote) == _without_timing(local)  # every float, bit for bit


def _fleet_logs(tmp: Path) -> list[Path]:
    logs = [
        DATA / "uavlogviewer_sitl_tlog" / "vtol.tlog",
        DATA / "corpus_2026" / "px4_v190_sitl_truth.ulg",
        DATA / "pyulog_samples" / "sample_log_small.ulg",
        DATA / "corpus_2026" / "ap_plane423_2022_ground_noimu.bin",
    ]
    if not all(p.is_file() for p in logs):
        pytest.skip(f"the real logs of {DATA} are not beside this checkout")
    bad = tmp / "notes.txt"  # a fifth "log" that is not one: recorded, the fleet goes on
    bad.write_text("not a log\n")
    return [*logs, bad]


def _fleet_tables(out: Path) -> dict[str, Any]:
    """Every run's estimate and the fleet's rows, without what measures time."""
    found: dict[str, Any] = {}
    for path in sorted((out / "logs").rglob("estimate.parquet")):
        found[str(path.relative_to(out))] = pq.read_table(path)
    rows = json.loads((out / "fleet.json").read_text())
    found["logs"] = [{k: v for k, v in r.items() if k != "analysis_s"} for r in rows["logs"]]
    found["failed"] = [(f["name"], f["error"]) for f in rows["failed"]]
    return found


def test_a_fleet_on_the_cluster_equals_the_embedded_default(cluster: str, tmp_path: Path) -> None:
    from navreplay.pipeline.fleet import fleet
    from navreplay.pipeline.params import load_params

    logs = _fleet_logs(tmp_path)
    params = load_params(None)
    kw: dict[str, Any] = {"filters": ["lc_ekf"], "scenarios": ["nominal"]}
    here = fleet(logs, tmp_path / "here", params, workers=2, **kw)
    there = fleet(logs, tmp_path / "there", params, scheduler=cluster, **kw)
    assert [r["name"] for r in here.rows] == [
        "vtol", "px4_v190_sitl_truth", "sample_log_small", "ap_plane423_2022_ground_noimu",
    ]  # fmt: skip
    assert [f["name"] for f in there.failed] == ["notes"]
    assert "UnsupportedFormatError" in there.failed[0]["error"]
    a, b = _fleet_tables(tmp_path / "here"), _fleet_tables(tmp_path / "there")
    assert a.keys() == b.keys()
    assert len(a) >= 4  # estimates of the logs that ran, and the rows
    for key in a:
        if key in ("logs", "failed"):
            assert a[key] == b[key], key
        else:
            assert a[key].equals(b[key]), key
    assert (tmp_path / "there" / "summary" / "index.html").is_file()
    assert (tmp_path / "there" / "logs" / "vtol" / "report" / "index.html").is_file()


def test_a_worker_killed_mid_sweep_loses_nothing(cluster: str) -> None:
    from distributed import Client

    with Client(cluster) as c:
        pids = c.run(os.getpid)
    victim = sorted(pids.values())[0]
    killed: list[int] = []

    def kill_once(_line: str) -> None:
        if not killed:  # at the first finished start: the sweep is under way
            os.kill(victim, signal.SIGKILL)
            killed.append(victim)

    starts = tuple(30.0 + 3.0 * k for k in range(12))
    local = montecarlo_rows("lc_ekf", DRIVE_S, starts, CASES, tail_s=5.0)
    remote = montecarlo_rows("lc_ekf", DRIVE_S, starts, CASES, tail_s=5.0, scheduler=cluster,
                             progress=kill_once, progress_every_s=0.0)  # fmt: skip
    assert killed == [victim]
    with pytest.raises(ProcessLookupError):
        os.kill(victim, 0)  # it is gone
    assert _without_timing(remote) == _without_timing(local)


def _self_signed(tmp: Path) -> list[str]:
    """A self-signed certificate for 127.0.0.1 as authority, certificate and key of all."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "navreplay test cluster")])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName([x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    cert_pem = tmp / "cert.pem"
    key_pem = tmp / "key.pem"
    cert_pem.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_pem.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return [str(cert_pem), str(key_pem)]


def test_a_scheduler_over_tls_with_a_self_signed_certificate(tmp_path: Path) -> None:
    from distributed.security import Security

    cert, key = _self_signed(tmp_path)
    tls = ["--tls-ca-file", cert, "--tls-cert", cert, "--tls-key", key]
    address, procs = _start_cluster(tmp_path, 1, tls)
    try:
        assert address.startswith("tls://127.0.0.1:")
        sec = Security(tls_ca_file=cert, tls_client_cert=cert, tls_client_key=key,
                       require_encryption=True)  # fmt: skip
        _wait_for_workers(address, 1, sec)
        params = ComputeParams(scheduler=address, tls_ca_file=cert, tls_cert=cert, tls_key=key)
        assert run_tasks(operator.mul, 3, [1, 2, 5], scheduler=address, params=params) == [3, 6, 15]
        # without certificates a tls:// scheduler is a clear error, not a traceback
        from navreplay.pipeline.compute import ComputeError

        with pytest.raises(ComputeError, match="needs the cluster's certificates"):
            run_tasks(operator.mul, 3, [1], scheduler=address, params=ComputeParams())
    finally:
        _stop(procs)
