"""The campaign directory and the runner's bookkeeping: parts written whole, resuming, one spec
per directory, batches, convergence verdicts, and the command's errors."""

from __future__ import annotations

import math

import pyarrow.parquet as pq
import pytest

from companion.campaign.runner import CampaignRun, convergence_verdicts
from companion.campaign.spec import CampaignSpec
from companion.campaign.store import SCHEMA, CampaignStore, StoreError
from companion.cli import main as cli_main


def fake_row(i: int, *, u: bool, m: bool, traffic: str = "drone", weight: float = 1.0) -> dict:
    row = {name: None for name in SCHEMA.names}
    row.update(
        {
            "id": i,
            "stratum": "crossing/open",
            "source": "parametric",
            "traffic": traffic,
            "world": "open",
            "mission": "open",
            "seed": 1,
            "spec_hash": "h",
            "weight": weight,
            "n_threats": 1,
        }
    )
    for p, flag in (("u_", u), ("m_", m)):
        row.update(
            {
                f"{p}collision": flag,
                f"{p}nmac": flag,
                f"{p}lowc": flag,
                f"{p}min_sep_m": 1.0,
                f"{p}hmd_m": [1.0],
                f"{p}vmd_m": [0.5],
                f"{p}obstacle_entries": 0,
                f"{p}fence_entries": 0,
                f"{p}completed": True,
                f"{p}path_m": 100.0,
            }
        )
    row.update(
        {
            "m_alerted": m,
            "m_alert_t_s": math.nan,
            "m_manoeuvred": m,
            "m_decisions": ["evade"] if m else [],
            "m_latency_ms": [60.0] if m else [],
            "m_decide_wall_ms": [5.0] if m else [],
            "m_extra_path_m": 0.0,
            "noise_pos_m": 0.0,
            "noise_vel_m_s": 0.0,
            "update_hz": 2.0,
            "latency_s": 0.0,
            "dropout": 0.0,
            "wall_ms": 100.0,
            "cpu_ms": 90.0,
        }
    )
    return row


def test_open_writes_the_spec_and_refuses_another(tmp_path):
    store = CampaignStore(tmp_path / "c")
    digest = store.open(CampaignSpec(name="a"))
    assert (tmp_path / "c" / "spec.toml").exists()
    assert store.open(CampaignSpec(name="a")) == digest  # reopening the same spec is fine
    assert store.spec() == CampaignSpec(name="a")
    with pytest.raises(StoreError, match="another spec"):
        store.open(CampaignSpec(name="b"))


def test_parts_are_whole_and_sorted(tmp_path):
    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    store.append(10, [fake_row(i, u=True, m=False) for i in range(10, 20)])
    store.append(0, [fake_row(i, u=True, m=i == 3) for i in range(10)])
    assert store.done_batches() == {0, 10}
    table = store.table()
    assert table.column("id").to_pylist() == list(range(20))
    assert not list((tmp_path / "c" / "rows").glob("*.tmp"))
    assert pq.read_table(store.part_path(0)).num_rows == 10


def test_a_broken_part_is_named(tmp_path):
    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    store.part_path(0).write_bytes(b"not parquet")
    with pytest.raises(StoreError, match="part-0000000.parquet: unreadable"):
        store.table()


def test_a_pack_holds_the_same_rows_and_its_batches_stay_done(tmp_path):
    spec = CampaignSpec(max_pairs=50, min_pairs=10, batch_pairs=10)
    store = CampaignStore(tmp_path / "c")
    store.open(spec)
    for first in (0, 10, 30):
        store.append(first, [fake_row(i, u=True, m=i == first) for i in range(first, first + 10)])
    before = store.table()
    pack = store.pack()
    assert pack.name == "pack-0000000.parquet"
    assert not list(store.rows_dir.glob("part-*"))
    assert repr(store.table().to_pylist()) == repr(before.to_pylist())  # (NaN equal to NaN)
    assert store.done_batches() == {0, 10, 30}
    assert CampaignRun(spec, store, workers=1).pending() == [(20, 10), (40, 10)]
    store.append(20, [fake_row(i, u=True, m=False) for i in range(20, 30)])
    assert store.pack().name == "pack-0000020.parquet"  # a second pack beside the first
    assert store.pack() is None  # nothing left to pack
    assert store.table().column("id").to_pylist() == list(range(40))
    assert store.done_batches() == {0, 10, 20, 30}


def test_a_broken_pack_is_named(tmp_path):
    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    (store.rows_dir / "pack-0000000.parquet").write_bytes(b"not parquet")
    with pytest.raises(StoreError, match="pack-0000000.parquet: unreadable pack"):
        store.done_batches()


def test_pending_batches_skip_the_stored_ones(tmp_path):
    spec = CampaignSpec(max_pairs=45, min_pairs=10, batch_pairs=10)
    store = CampaignStore(tmp_path / "c")
    run = CampaignRun(spec, store, workers=1)
    assert run.pending() == [(0, 10), (10, 10), (20, 10), (30, 10), (40, 5)]
    store.append(10, [fake_row(i, u=True, m=False) for i in range(10, 20)])
    assert run.pending() == [(0, 10), (20, 10), (30, 10), (40, 5)]
    assert run._contiguous(store.done_batches()) == 0  # a gap at 0: nothing contiguous
    store.append(0, [fake_row(i, u=True, m=False) for i in range(10)])
    assert run._contiguous(store.done_batches()) == 20
    assert CampaignRun(spec, store, workers=1, max_pairs=25).pending() == [(20, 5)]


def test_a_killed_run_logs_its_start_and_why_it_stopped(tmp_path, monkeypatch):
    spec = CampaignSpec(max_pairs=40, min_pairs=10, batch_pairs=10)
    store = CampaignStore(tmp_path / "c")
    store.open(spec)
    run = CampaignRun(spec, store, workers=1)

    def submit(first, n):
        raise KeyboardInterrupt  # Ctrl-C while the batches go out

    monkeypatch.setattr(run, "_executor", lambda: (submit, lambda: None))
    with pytest.raises(KeyboardInterrupt):
        run.run()
    events = [r["event"] for r in store.runs()]
    assert events == ["start", "interrupted"]
    assert store.runs()[1]["reason"] == "KeyboardInterrupt" and store.runs()[0]["code"]


def test_verdicts_per_traffic_kind(tmp_path):
    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    store.append(
        0,
        [fake_row(i, u=True, m=i % 10 == 0) for i in range(400)]
        + [fake_row(i, u=i % 2 == 0, m=False, traffic="rotorcraft") for i in range(400, 420)],
    )
    verdicts = convergence_verdicts(store.table(), 0.05)
    assert set(verdicts) == {"drone nmac", "drone lowc", "rotorcraft nmac", "rotorcraft lowc"}
    assert not verdicts["rotorcraft nmac"].converged  # 20 pairs are not enough


@pytest.mark.parametrize(
    "argv, message",
    [
        (["campaign", "run", "nope.toml", "--out", "x"], "nope.toml: no such file"),
        (["campaign", "run", "SPEC", "--out", "x", "--workers", "0"], "--workers: must be >= 1"),
        (["campaign", "status", "DIR"], "not a campaign directory"),
        (["campaign", "pack", "DIR"], "not a campaign directory"),
    ],
)
def test_command_errors_name_what_is_wrong(tmp_path, capsys, argv, message):
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "x"\n')
    argv = [str(spec) if a == "SPEC" else str(tmp_path / "nodir") if a == "DIR" else a for a in argv]
    code = cli_main(argv)
    assert code == 2
    assert message in capsys.readouterr().err


def test_the_pack_command_packs_and_says_how_many(tmp_path, capsys):
    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    store.append(0, [fake_row(i, u=True, m=False) for i in range(20)])
    assert cli_main(["campaign", "pack", str(store.root)]) == 0
    assert "20 pairs stored" in capsys.readouterr().out
    assert cli_main(["campaign", "pack", str(store.root)]) == 0
    assert "nothing to pack" in capsys.readouterr().out


def test_a_part_written_before_cpu_ms_reads_with_nulls(tmp_path):
    import pyarrow as pa

    store = CampaignStore(tmp_path / "c")
    store.open(CampaignSpec())
    old = pa.Table.from_pylist([fake_row(i, u=True, m=False) for i in range(3)], schema=SCHEMA).drop_columns(["cpu_ms"])
    pq.write_table(old, store.part_path(0))
    store.append(3, [fake_row(i, u=True, m=False) for i in range(3, 6)])
    cpu = store.table().column("cpu_ms").to_pylist()
    assert cpu[:3] == [None] * 3 and cpu[3:] == [90.0] * 3


def test_rows_of_other_code_are_not_resumed(tmp_path, monkeypatch):
    """A campaign is one version of the code: reopening its directory with other code is refused,
    naming both versions and the commit to pin; the same code resumes."""
    from companion.campaign import store as store_module

    store = CampaignStore(tmp_path)
    monkeypatch.setattr(store_module, "code_hash", lambda: "c0de00000001")
    monkeypatch.setattr(store_module, "code_version", lambda: "abc1234")
    store.open(CampaignSpec())
    store.log_run({"event": "start"})  # a run killed before its end record
    store.append(0, [fake_row(0, u=True, m=False)])
    assert store.open(CampaignSpec())  # the same code: resumed
    monkeypatch.setattr(store_module, "code_version", lambda: "fed4321")
    assert store.open(CampaignSpec())  # another commit, the same flight code
    monkeypatch.setattr(store_module, "code_hash", lambda: "c0de00000002")
    with pytest.raises(StoreError, match=r"code c0de00000001, at commit abc1234.*code c0de00000002"):
        store.open(CampaignSpec())
    assert store.runs()[0]["commit"] == "abc1234"


def test_the_code_hash_follows_the_flight_code_not_the_storage(tmp_path):
    from companion.campaign.store import code_hash

    for rel in ("companion/flight/x.py", "companion/campaign/store.py", "companion/commands/c.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("a = 1\n")
    before = code_hash(tmp_path)
    (tmp_path / "companion/campaign/store.py").write_text("a = 2\n")
    (tmp_path / "companion/commands/c.py").write_text("a = 2\n")
    assert code_hash(tmp_path) == before  # storage and commands make no row
    (tmp_path / "companion/flight/x.py").write_text("a = 2\n")
    assert code_hash(tmp_path) != before


def test_the_code_version_names_the_commit_and_a_diff():
    from companion.campaign.store import code_version

    version = code_version()
    commit, _, diff = version.partition("+")
    assert len(commit) >= 7 and all(c in "0123456789abcdef" for c in commit)
    assert diff == "" or len(diff) == 8
