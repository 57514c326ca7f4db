"""The campaign on a real Dask cluster (issue 23): a ``dask scheduler`` and two ``dask worker``
processes on loopback run a 200-encounter campaign through ``companion campaign run --cluster``;
its rows are identical to the same spec's rows run on the local process pool (every column but
the measured ones), and a killed run resumes to the same rows.

The spec takes cheap strata (open air, crossing and far pop-ups, and rotorcraft traffic heard as
ADSB_VEHICLE) so that both runs fit in a few minutes on two cores.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest
from support import REPO_ROOT

from companion.campaign.flying import MEASURED_COLUMNS
from companion.campaign.store import CampaignStore
from companion.sitl.processes import ManagedProcess
from heli_common.ports import free_port

pytestmark = [pytest.mark.integration, pytest.mark.timeout(900)]

SPEC = """name = "cluster-check"
seed = 5
max_pairs = 200
min_pairs = 200
batch_pairs = 10
check_every = 100
strata = ["crossing/open", "popup_far/open", "head_on/open", "manned/rotorcraft"]
"""


def _companion(*args, timeout_s: float = 900.0) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "companion.cli", "campaign", *args, "--no-progress"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout)


def _rows(directory) -> list[str]:
    """Every row but its measured columns, as JSON text (a NaN equals a NaN)."""
    table = CampaignStore(directory).table()
    return [json.dumps(r, sort_keys=True) for r in table.drop_columns(list(MEASURED_COLUMNS)).to_pylist()]


@pytest.fixture
def cluster(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    scheduler = ManagedProcess(
        [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], tmp_path / "scheduler.log"
    ).start()
    workers = [
        ManagedProcess(
            [
                dask,
                "worker",
                address,
                "--nworkers",
                "1",
                "--nthreads",
                "1",
                "--no-dashboard",
                "--name",
                f"w{i}",
                "--local-directory",
                str(tmp_path / f"w{i}"),
            ],
            tmp_path / f"worker{i}.log",
            cwd=REPO_ROOT,
        ).start()
        for i in range(2)
    ]
    try:
        scheduler.wait_ready(scheduler.log_contains("Scheduler at"), 60.0, "dask scheduler")
        for w in workers:
            w.wait_ready(w.log_contains("Starting established connection"), 60.0, "dask worker")
        yield address
    finally:
        for p in (*workers, scheduler):
            p.stop()


def test_cluster_rows_equal_local_rows(tmp_path, cluster):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC)
    on_cluster = _companion("run", str(spec), "--out", str(tmp_path / "cluster"), "--cluster", cluster)
    assert on_cluster["flown"] == 200 and on_cluster["workers"] == 2
    local = _companion("run", str(spec), "--out", str(tmp_path / "local"), "--workers", "2")
    assert local["flown"] == 200
    cluster_rows, local_rows = _rows(tmp_path / "cluster"), _rows(tmp_path / "local")
    assert cluster_rows == local_rows
    local_rows = [json.loads(r) for r in local_rows]
    assert [r["id"] for r in local_rows] == list(range(200))
    # the rows hold every stratum, flown both ways, with ADS-B traffic among them
    assert {r["stratum"] for r in local_rows} == {
        "crossing/open",
        "popup_far/open",
        "head_on/open",
        "manned/rotorcraft",
    }
    assert any(r["u_nmac"] for r in local_rows) and any(r["m_manoeuvred"] for r in local_rows)
    assert all(r["weight"] > 0 for r in local_rows)
    status = subprocess.run(
        [sys.executable, "-m", "companion.cli", "campaign", "status", str(tmp_path / "local"), "--json"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert status.returncode == 0, status.stderr[-2000:]
    assert json.loads(status.stdout)["pairs"] == 200


def test_killed_campaign_resumes_to_the_same_rows(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.replace("max_pairs = 200", "max_pairs = 60").replace("min_pairs = 200", "min_pairs = 60"))
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "campaign",
            "run",
            str(spec),
            "--out",
            str(out),
            "--workers",
            "2",
            "--no-progress",
        ],
        cwd=REPO_ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and len(list((out / "rows").glob("part-*.parquet"))) < 2:
        time.sleep(0.5)
    os.killpg(proc.pid, 9)
    proc.wait(30)
    parts = sorted((out / "rows").glob("part-*.parquet"))
    assert 2 <= len(parts) < 6, "the campaign should have been killed part way"
    for path in parts:
        assert pq.read_table(path).num_rows == 10  # only whole parts are left
    resumed = _companion("run", str(spec), "--out", str(out), "--workers", "2")
    assert resumed["flown"] == 60 - 10 * len(parts)
    fresh = _companion("run", str(spec), "--out", str(tmp_path / "fresh"), "--workers", "2")
    assert fresh["flown"] == 60
    assert _rows(out) == _rows(tmp_path / "fresh")
