"""A campaign directory: its spec, and its rows appended to Parquet as batches finish.

Layout of ``DIR``::

    spec.toml              the spec as run (its hash is on every row)
    settings.toml          the companion's settings file's text, when the spec names one
    rows/part-0000020.parquet   one file per finished batch (its first encounter id)
    rows/pack-0000000.parquet   many batches packed into one file (``pack``; their first ids in
                                its metadata), small enough to keep in a repository
    runs.jsonl             one line per run: when, the code's commit, workers, pairs, wall time
    report/                ``companion campaign report``'s output

A part is written to a temporary name and renamed, so a killed campaign leaves only whole
parts; resuming skips the batches whose part exists (alone or in a pack). Rows depend only on the spec and the
encounter id, so parts written by any number of workers, or by a Dask cluster, are the same.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import subprocess
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from companion.campaign.spec import CampaignSpec, SpecError, load_spec, spec_hash, spec_to_toml

__all__ = ["SCHEMA", "CampaignStore", "StoreError"]


class StoreError(SpecError):
    """A campaign directory cannot be used (another spec's rows, a broken part)."""


_FLOAT_LIST = pa.list_(pa.float64())
_RUN_COLUMNS = [
    ("collision", pa.bool_()),
    ("nmac", pa.bool_()),
    ("lowc", pa.bool_()),
    ("min_sep_m", pa.float64()),
    ("hmd_m", _FLOAT_LIST),
    ("vmd_m", _FLOAT_LIST),
    ("obstacle_entries", pa.int64()),
    ("fence_entries", pa.int64()),
    ("completed", pa.bool_()),
    ("path_m", pa.float64()),
]
#: One row per encounter pair.
SCHEMA = pa.schema(
    [
        ("id", pa.int64()),
        ("stratum", pa.string()),
        ("source", pa.string()),
        ("traffic", pa.string()),
        ("world", pa.string()),
        ("mission", pa.string()),
        ("seed", pa.int64()),
        ("spec_hash", pa.string()),
        ("weight", pa.float64()),
        ("n_threats", pa.int64()),
    ]
    + [(f"{p}{name}", kind) for p in ("u_", "m_") for name, kind in _RUN_COLUMNS]
    + [
        ("m_alerted", pa.bool_()),
        ("m_alert_t_s", pa.float64()),
        ("m_manoeuvred", pa.bool_()),
        ("m_decisions", pa.list_(pa.string())),
        ("m_latency_ms", _FLOAT_LIST),
        ("m_decide_wall_ms", _FLOAT_LIST),
        ("m_extra_path_m", pa.float64()),
        ("noise_pos_m", pa.float64()),
        ("noise_vel_m_s", pa.float64()),
        ("update_hz", pa.float64()),
        ("latency_s", pa.float64()),
        ("dropout", pa.float64()),
        ("wall_ms", pa.float64()),
        ("cpu_ms", pa.float64()),
    ]
)
#: Measured columns a part written before they existed may lack (read as nulls).
LATER_COLUMNS = ("cpu_ms",)
#: A pack's metadata key holding its batches' first ids (JSON list).
PACK_KEY = b"companion.batches"


class CampaignStore:
    """The directory ``root`` of one campaign.

    Parameters
    ----------
    root : path
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.rows_dir = self.root / "rows"

    # ------------------------------------------------------------------ the spec
    def open(self, spec: CampaignSpec, settings_text: str = "") -> str:
        """Make or reopen the directory for ``spec``; returns the spec's hash.

        Raises
        ------
        StoreError
            The directory holds another spec's campaign, or rows flown by other code (rows of
            two versions of the code are not one campaign).
        """
        digest = spec_hash(spec, settings_text)
        self._check_code()
        self.rows_dir.mkdir(parents=True, exist_ok=True)
        spec_file = self.root / "spec.toml"
        if spec_file.exists():
            held = spec_hash(load_spec(spec_file), self.settings_text())
            if held != digest:
                raise StoreError(
                    f"{self.root}: holds the campaign of another spec (hash {held}, this one {digest}); "
                    "use another --out directory"
                )
        else:
            self._write_text(spec_file, spec_to_toml(spec))
            if settings_text:
                self._write_text(self.root / "settings.toml", settings_text)
        return digest

    def _check_code(self) -> None:
        last = next((run for run in reversed(self.runs()) if run.get("code")), None)
        here = code_hash()
        if last is not None and last["code"] != here and self.done_batches():
            commit = last.get("commit", "")
            raise StoreError(
                f"{self.root}: its rows were flown by other code (code {last['code']}, at commit "
                f"{commit or '?'}), this is code {here}; resume it with that code "
                f"(git worktree add DIR {commit.split('+')[0] or 'COMMIT'}) or use another --out "
                "directory"
            )

    def spec(self) -> CampaignSpec:
        """The spec the directory was made for."""
        path = self.root / "spec.toml"
        if not path.exists():
            raise StoreError(f"{self.root}: not a campaign directory (no spec.toml)")
        return load_spec(path)

    def settings_text(self) -> str:
        path = self.root / "settings.toml"
        return path.read_text() if path.exists() else ""

    @staticmethod
    def _write_text(path: Path, text: str) -> None:
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)

    def log_run(self, record: dict) -> None:
        """Append one record to ``runs.jsonl``, stamped with the time, the commit and the code's hash
        (``code_hash``): a run logs one when it starts and one when it ends."""
        line = {
            "at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "commit": code_version(),
            "code": code_hash(),
            **record,
        }
        with open(self.root / "runs.jsonl", "a", encoding="utf-8") as fh:
            fh.write(json.dumps(line) + "\n")

    def runs(self) -> list[dict]:
        path = self.root / "runs.jsonl"
        if not path.exists():
            return []
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]

    # ------------------------------------------------------------------ rows
    def part_path(self, first_id: int) -> Path:
        return self.rows_dir / f"part-{first_id:07d}.parquet"

    def done_batches(self) -> set[int]:
        """First ids of the batches whose rows are written (in a part of their own or in a pack)."""
        out = set(self._parts())
        for path in self._packs():
            out.update(self._pack_batches(path))
        return out

    def _parts(self) -> dict[int, Path]:
        """The batches' own parts by first id (files not named ``part-<id>.parquet`` left out)."""
        out = {}
        for path in sorted(self.rows_dir.glob("part-*.parquet")):
            try:
                out[int(path.stem.split("-")[1])] = path
            except (IndexError, ValueError):
                continue
        return out

    def _packs(self) -> list[Path]:
        return sorted(self.rows_dir.glob("pack-*.parquet"))

    @staticmethod
    def _pack_batches(path: Path) -> list[int]:
        try:
            meta = pq.read_schema(path).metadata or {}
            return [int(first) for first in json.loads(meta[PACK_KEY])]
        except (pa.ArrowInvalid, OSError, KeyError, ValueError, TypeError) as exc:
            raise StoreError(f"{path}: unreadable pack ({exc!r}); restore it from where it was kept") from None

    def pack(self) -> Path | None:
        """Pack every batch's part into one new ``pack-*.parquet`` (zstd) and delete the parts.

        The rows are unchanged (``table()`` is the same before and after) and resuming skips the
        packed batches. A pack of 10^5 pairs is about 13 MB. Returns the pack, or None when there
        were no parts.
        """
        parts = self._parts()
        if not parts:
            return None
        firsts = sorted(parts)
        table = self._read_parts(list(parts.values()))
        path = self.rows_dir / f"pack-{firsts[0]:07d}.parquet"
        n = 0
        while path.exists():
            n += 1
            path = self.rows_dir / f"pack-{firsts[0]:07d}-{n}.parquet"
        table = table.replace_schema_metadata({PACK_KEY: json.dumps(firsts).encode()})
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp, compression="zstd", compression_level=19)
        os.replace(tmp, path)
        for part in parts.values():
            part.unlink()
        return path

    def append(self, first_id: int, rows: list[dict]) -> Path:
        """Write one batch's rows (atomically)."""
        table = pa.Table.from_pylist(rows, schema=SCHEMA)
        path = self.part_path(first_id)
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, path)
        return path

    def table(self) -> pa.Table:
        """Every row written, by id."""
        return self._read_parts(sorted(self.rows_dir.glob("part-*.parquet")) + self._packs())

    @staticmethod
    def _read_parts(paths: list[Path]) -> pa.Table:
        if not paths:
            return SCHEMA.empty_table()
        tables = []
        for path in paths:
            try:
                table = pq.read_table(path)
                for name in LATER_COLUMNS:
                    if name not in table.column_names:
                        table = table.append_column(name, pa.nulls(table.num_rows, pa.float64()))
                tables.append(table.select(SCHEMA.names).cast(SCHEMA))
            except (pa.ArrowInvalid, pa.ArrowTypeError, KeyError, OSError) as exc:
                remedy = (
                    "restore it from where it was kept, or delete it and resume to fly its batches again"
                    if path.name.startswith("pack-")
                    else "delete it and resume to fly its batch again"
                )
                raise StoreError(f"{path}: unreadable {path.name.split('-')[0]} ({exc}); {remedy}") from None
        return pa.concat_tables(tables).sort_by("id")


#: The code whose changes make another campaign (a diff elsewhere, e.g. in docs, does not).
CODE_DIRS = ("companion", "heli_model", "heli_common", "mavlink_signing", "sim_vehicle")
#: Modules that only drive, store, read, report or replay rows: changing them changes no row (the
#: runner chooses which batches fly where; a test shows that where changes no row).
ROWLESS_MODULES = (
    "companion/campaign/runner.py",
    "companion/campaign/store.py",
    "companion/campaign/report.py",
    "companion/campaign/report_plots.py",
    "companion/campaign/summary.py",
    "companion/campaign/labels.py",
    "companion/campaign/replay.py",
    "companion/commands",
)
_ROOT = Path(__file__).resolve().parents[2]


def code_hash(root: Path = _ROOT) -> str:
    """A hash of the Python source that makes the rows (``CODE_DIRS`` without ``ROWLESS_MODULES``),
    read from the files themselves: two trees with the same flight code give the same hash, whatever
    their commits, and rows of two hashes are not one campaign."""
    digest = hashlib.sha1()
    for d in CODE_DIRS:
        for path in sorted((root / d).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            if any(rel == m or rel.startswith(m + "/") for m in ROWLESS_MODULES):
                continue
            digest.update(rel.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=_ROOT, capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.decode(errors="replace") if out.returncode == 0 else None


def code_version() -> str:
    """The code's git commit, with ``+<hash of the diff>`` when the code differs from it ("" outside a
    checkout), for a person to find the code again (``code_hash`` is what must match)."""
    commit = (_git("rev-parse", "--short", "HEAD") or "").strip()
    if not commit:
        return ""
    diff = _git("diff", "HEAD", "--", *CODE_DIRS)
    if diff:
        return f"{commit}+{hashlib.sha1(diff.encode()).hexdigest()[:8]}"
    return commit
