"""companion.sitl.vehicles: the command lines of sim-vehicle and companion run, and that the
package starts sim-vehicle as a process, never importing it."""

from __future__ import annotations

import ast
from pathlib import Path

import companion.sitl
from companion.sitl.vehicles import companion_run_args, home_arg, sim_vehicle_args


def test_sim_vehicle_args():
    args = sim_vehicle_args(
        40001,
        outs=["127.0.0.1:40002", "127.0.0.1:14550"],
        speedup=2.0,
        instance=1,
        home=home_arg((47.3977420, 8.5455940, 488.0), 300.0),
        tlog="sim1.tlog",
        seed=8,
        config="hold.toml",
        extra=["-v"],
    )
    assert args == [
        "sim_vehicle.cli",
        "--instance",
        "1",
        "--home",
        "47.397742,8.545594,488,300",
        "--port",
        "40001",
        "--out",
        "127.0.0.1:40002",
        "--out",
        "127.0.0.1:14550",
        "--speedup",
        "2",
        "--tlog",
        "sim1.tlog",
        "--seed",
        "8",
        "--config",
        "hold.toml",
        "-v",
    ]
    assert sim_vehicle_args(5, speedup=4) == ["sim_vehicle.cli", "--port", "5", "--speedup", "4"]
    assert "--no-default-out" in sim_vehicle_args(5, default_outs=False)
    assert "--no-default-out" not in sim_vehicle_args(5, outs=["127.0.0.1:6"], default_outs=False)


def test_companion_run_args():
    args = companion_run_args(
        "udpin://127.0.0.1:40002",
        instance=1,
        mission=Path("m.plan"),
        zenoh_connect="tcp/127.0.0.1:1",
        zenoh_listen="tcp/127.0.0.1:2",
        record="r.jsonl",
        time_scale=2.0,
        seed=8,
        extra=["--no-fleet"],
    )
    assert args == [
        "companion.cli",
        "run",
        "--instance",
        "1",
        "--connect",
        "udpin://127.0.0.1:40002",
        "--mission",
        "m.plan",
        "--zenoh-connect",
        "tcp/127.0.0.1:1",
        "--zenoh-listen",
        "tcp/127.0.0.1:2",
        "--record",
        "r.jsonl",
        "--time-scale",
        "2",
        "--seed",
        "8",
        "--no-fleet",
    ]
    assert companion_run_args("udpin://127.0.0.1:1") == ["companion.cli", "run", "--connect", "udpin://127.0.0.1:1"]


def test_the_package_never_imports_sim_vehicle():
    for path in Path(companion.sitl.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            assert not any(n.split(".")[0] == "sim_vehicle" for n in names), f"{path.name} imports {names}"
