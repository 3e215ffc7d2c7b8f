"""Every example printed by ``canest --help`` and by each command's ``--help`` is run, as printed.

The offline examples run here (``simulate``'s first, the others in the order they are printed) in one folder
set up as they assume: the repository's ``configs/``, the files the earlier examples wrote, and a few
stand-ins under the names the examples use (``my_car.yaml`` is the built-in config, ``drive1.log``... and
``drive.blf`` short simulated drives, ``live.csv`` an estimate CSV on epoch time, ``logs/`` a small fleet).
An example that needs a CAN bus, a Dask scheduler or a second process is run by the test ``ELSEWHERE`` names
(checked to exist); the README's two first-screen commands are CI's own (``make test``) and
``test_service_virtual``'s (``canest demo``).
"""
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np

from canest.cli import COMMANDS, DESCRIPTION, build_parser
from tests.conftest import ROOT, ford_dbc

ELSEWHERE = {
    "canest demo": "tests/test_service_virtual.py::test_demo_runs_and_reports_accuracy",
    "canest replay drive.log --realtime -c vcan0":
        "tests/test_socketcan.py::test_daemon_with_canest_player_python_can_and_candump_capture",
    "canest replay drive.log --realtime -i udp_multicast -c 239.74.163.2 --rate 2":
        "tests/test_toolchain.py::test_daemon_monitor_and_player_as_three_processes_on_udp_multicast",
    "canest replay drive.log --realtime -i udp_multicast -c 239.74.163.2":
        "tests/test_toolchain.py::test_daemon_monitor_and_player_as_three_processes_on_udp_multicast",
    "candump -L vcan0 | canest replay - --csv - | head": "tests/test_socketcan.py::test_candump_pipe_into_replay",
    "canest batch 'fleet/**/*.log' --out results/ --scheduler tcp://scheduler:8786":
        "tests/test_batch.py::test_separate_process_cluster_survives_a_killed_worker",
    "canest run --config configs/dici_ev.yaml": "tests/test_socketcan.py::test_daemon_with_canplayer",
    "canest run --config my_car.yaml -c can0 --output-channel can0 -b 500000":
        "tests/test_toolchain.py::test_the_config_files_bus_overrides_python_cans_and_the_command_line_overrides_both",
    "canest run -i udp_multicast -c 239.74.163.2 --output-channel 239.74.163.3":
        "tests/test_toolchain.py::test_daemon_monitor_and_player_as_three_processes_on_udp_multicast",
    "canest monitor -i udp_multicast -c 239.74.163.3":
        "tests/test_toolchain.py::test_daemon_monitor_and_player_as_three_processes_on_udp_multicast",
    "canest monitor -c vcan1": "tests/test_faults.py::test_monitor_on_vcan1",
    "canest monitor --config configs/dici_ev.yaml": "tests/test_faults.py::test_monitor_on_vcan1",
    "canest monitor -c vcan1 --once": "tests/test_faults.py::test_monitor_on_vcan1",
}


def printed_examples():
    """(command, example) for every example line of the help texts, comments after `` #`` removed."""
    texts = {"canest": DESCRIPTION}
    for name in COMMANDS:
        parser = build_parser([name])
        texts[name] = next(action for action in parser._actions if action.choices and name in action.choices) \
            .choices[name].format_help()
    for command, text in sorted(texts.items(), key=lambda item: item[0] != "simulate"):  # the drives first
        for line in text.splitlines():
            words = line.strip()
            if words.startswith(("canest ", "candump ")) and line.startswith("  "):
                yield command, re.split(r"\s+#", words)[0].strip()


def shell(command: str, where, **kwargs) -> subprocess.CompletedProcess:
    """``command`` run by bash in ``where``, with this environment's ``canest`` first on the PATH."""
    return subprocess.run(command, shell=True, cwd=where, capture_output=True, text=True, env=environment(),
                          executable="/bin/bash", **kwargs)


def folder_as_the_examples_assume(where):
    def run(command):
        shell(command, where, check=True)

    os.symlink(ROOT / "configs", where / "configs")
    shutil.copy(ROOT / "configs" / "dici_ev.yaml", where / "my_car.yaml")
    (where / "my_car.yaml").write_text((where / "my_car.yaml").read_text().replace("../dbc/", f"{ROOT}/dbc/"))
    shutil.copy(ford_dbc(), where / ford_dbc().name)
    for index in (1, 2, 3):  # calibrate's: country roads, which pin every parameter down (a DLC does not)
        run(f"canest simulate -m country --duration 30 --seed {index + 2} -o drive{index}.log "
            f"--truth drive{index}.csv")
    run("canest simulate -m dlc --seed 5 -o drive.blf --truth drive.blf.truth.csv")
    for folder, name in (("logs/day1", "a.log"), ("logs/day2", "b.log"), ("logs", "c.blf")):
        (where / folder).mkdir(parents=True, exist_ok=True)
        run(f"canest simulate -m dlc --seed 7 -o {folder}/{name} --truth {folder}/{name.split('.')[0]}.truth.csv")


def environment():
    return {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}{os.pathsep}{os.environ['PATH']}",
            "MPLBACKEND": "Agg"}


def live_csv_from(estimates, live):
    """An estimate CSV as ``canest run --csv`` writes it: the same rows on epoch time."""
    lines = estimates.read_text().splitlines()
    shifted = [lines[0]] + [f"{float(row.split(',', 1)[0]) + 1.8e9:.6f},{row.split(',', 1)[1]}" for row in lines[1:]]
    live.write_text("\n".join(shifted) + "\n")


def test_every_printed_example_is_run_here_or_by_the_test_named():
    examples = [example for _, example in printed_examples()]
    assert len(examples) > 30 and "canest demo" in examples
    for example, test in ELSEWHERE.items():
        assert example in examples, f"ELSEWHERE names an example no help prints: {example}"
        path, name = test.split("::")
        assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), re.M), f"{test} does not exist"


def test_the_offline_examples_run_as_printed(tmp_path):
    folder_as_the_examples_assume(tmp_path)
    failed = []
    for command, example in printed_examples():
        if example in ELSEWHERE:
            continue
        if example.startswith("canest evaluate live.csv"):
            live_csv_from(tmp_path / "est.csv", tmp_path / "live.csv")
        result = shell(example, tmp_path, timeout=600)
        if result.returncode != 0:
            failed.append(f"{example}\n    exit {result.returncode}: {result.stderr.strip()[-400:]}")
    assert not failed, "\n".join(failed)
    assert (tmp_path / "est.png").stat().st_size > 0 and (tmp_path / "results").is_dir()
    scores = [json.loads(shell(f"canest evaluate {estimates} truth.csv --json {align}", tmp_path, check=True).stdout)
              for estimates, align in (("live.csv", "--align first"), ("est.csv", ""))]
    assert scores[0]["vx"]["samples"] > 100 and scores[0].keys() == scores[1].keys()
    for state, aligned in scores[0].items():  # equal but for the epoch's rounding (6 decimals of 1.8e9 s)
        assert all(np.isclose(aligned[key], scores[1][state][key], rtol=1e-5) for key in ("rmse", "samples")), state
