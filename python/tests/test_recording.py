"""Recordings read by an independent reader: the ``mcap`` package of the MCAP project.

A real-time run of ``hcc run`` records itself into ``run.mcap`` while ``hcc
record`` records the same namespace as a second, pure subscriber. Both files
are read with ``mcap`` (not hcc's reader) and checked: channels and schemas,
message counts against the controller's own counters and the driver's
sequence numbers (with the gaps the recorder stored), the metadata. The run's
recording replays bit-identically, and a recorder killed with SIGKILL leaves
a file that reads up to its last chunk and that ``hcc plot`` turns into
results.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import signal
import subprocess
import time

import pytest
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader

from conftest import ROOT, binary, unique

CONFIG = ROOT / "config" / "paper-sim1.toml"
URDF = ROOT / "config" / "planar4.urdf"
TOPICS = {"/joint_state", "/torque_command", "/telemetry", "/setpoint", "/recorder", "/path", "/load"}


def env_with_prefix() -> dict[str, str]:
    return dict(os.environ, HCC_IPC_FILE_PREFIX=f"{unique('hccrec')}_"[:32])


def start_recorder(ns: str, out: pathlib.Path, env: dict[str, str], **kw) -> subprocess.Popen:
    """``hcc record`` on ``ns``, returned once it has subscribed (it creates
    its file after its subscribers), so that it sees the run from its start."""
    p = subprocess.Popen(
        [str(binary("hcc")), "record", "--namespace", ns, "--out", str(out),
         "--config", str(CONFIG), "--quiet"],
        cwd=ROOT, env=env, **kw,
    )
    deadline = time.monotonic() + 60
    while not out.exists():
        assert p.poll() is None, "hcc record ended before it subscribed"
        assert time.monotonic() < deadline, "hcc record did not start within 60 s"
        time.sleep(0.05)
    return p


def hcc(*args: str, env: dict[str, str], timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(binary("hcc")), *args], cwd=ROOT, env=env, capture_output=True, text=True,
        timeout=timeout,
    )


def read_all(path: pathlib.Path) -> dict:
    """Channels, schemas, metadata and decoded messages of a complete recording."""
    out: dict = {"messages": {t: [] for t in TOPICS}, "metadata": {}}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None, f"{path} has no summary section"
        out["channels"] = {c.topic: c for c in summary.channels.values()}
        out["schemas"] = {s.id: s for s in summary.schemas.values()}
        out["counts"] = {
            summary.channels[cid].topic: n
            for cid, n in summary.statistics.channel_message_counts.items()
        }
        for m in reader.iter_metadata():
            out["metadata"][m.name] = dict(m.metadata)
        for _schema, channel, message in reader.iter_messages():
            out["messages"][channel.topic].append(json.loads(message.data))
    return out


def check_recording(rec: dict, *, recorder: str, namespace: str) -> None:
    """What every recording of a run of paper-sim1 must show."""
    assert set(rec["channels"]) == TOPICS
    for topic, channel in rec["channels"].items():
        assert channel.message_encoding == "json", topic
        schema = rec["schemas"][channel.schema_id]
        assert schema.encoding == "jsonschema", topic
        assert schema.name.startswith("hcc."), topic
        assert "properties" in json.loads(schema.data), topic
    telemetry_schema = json.loads(rec["schemas"][rec["channels"]["/telemetry"].schema_id].data)
    level = telemetry_schema["properties"]["levels"]["items"]["properties"]
    assert {"error", "S", "tau"} <= set(level)
    assert {"tau_mu", "P_mu", "tau"} <= set(telemetry_schema["properties"])

    msgs = rec["messages"]
    for topic in TOPICS:
        assert rec["counts"].get(topic, 0) == len(msgs[topic]), topic
    states, commands, telemetry = msgs["/joint_state"], msgs["/torque_command"], msgs["/telemetry"]
    assert len(states) > 1000 and len(telemetry) > 1000

    # The recorder's own final count says what it lost; with it, nothing is unaccounted for.
    final = msgs["/recorder"][-1]
    assert final["last"] is True
    for name, stream in (("joint_state", states), ("torque_command", commands), ("telemetry", telemetry)):
        st = final[name]
        assert st["recorded"] == len(stream), name
        seqs = [m["seq"] for m in stream]
        assert seqs == sorted(seqs), name
        assert seqs[-1] - seqs[0] + 1 == len(set(seqs)) + st["gaps"], name

    # Message counts against the controller's own counters (last telemetry sample).
    last = telemetry[-1]
    c = last["counters"]
    assert c["sequence_errors"] == 0
    first = telemetry[0]
    cycles_seen = c["cycles"] - first["counters"]["cycles"] + 1
    stale_seen = c["stale_events"] - first["counters"]["stale_events"]
    assert len(telemetry) + final["telemetry"]["gaps"] == cycles_seen + stale_seen
    answered = [t for t in telemetry if not t["flags"] & 65536]
    assert len(commands) + final["torque_command"]["gaps"] >= len(answered)
    assert last["seq"] == telemetry[0]["seq"] + len(telemetry) + final["telemetry"]["gaps"] - 1

    # The paper's quantities under the names a viewer shows.
    assert len(last["levels"]) == 3
    for lv in last["levels"]:
        assert {"error", "S", "tau", "error_norm"} <= set(lv)
        assert len(lv["tau"]) == 4
    assert len(last["tau_mu"]) == 4 and isinstance(last["P_mu"], float)
    assert len(states[-1]["q"]) == 4

    meta = rec["metadata"]
    run = meta["hcc_run"]
    assert run["recorder"] == recorder
    assert run["namespace"] == namespace
    assert run["iceoryx2_version"] == "0.10.0"
    assert run["hcc_version"]
    assert run["start_time"].endswith("Z") and int(run["start_unix_ns"]) > 0
    scenario = meta["hcc_scenario"]
    assert scenario["toml"] == CONFIG.read_text()
    assert scenario["urdf_sha256"] == hashlib.sha256(URDF.read_bytes()).hexdigest()
    assert scenario["urdf_name"]
    machine = meta["hcc_machine"]
    assert int(machine["cpus"]) >= 1 and machine["kernel"]
    end = meta["hcc_recording_end"]
    assert end["end"]


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A 4 s real-time run of paper-sim1 under ``hcc run``, also recorded by ``hcc record``."""
    tmp = tmp_path_factory.mktemp("recording")
    env = env_with_prefix()
    ns = unique("rec")
    rec_file = tmp / "record.mcap"
    record = start_recorder(ns, rec_file, env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        run = hcc("run", str(CONFIG), "--duration", "4", "--namespace", ns,
                  "--out", str(tmp / "run"), "--no-plots", "--quiet", env=env)
        record_out, _ = record.communicate(timeout=60)
    finally:
        if record.poll() is None:
            record.kill()
            record.wait()
    assert run.returncode == 0, run.stdout + run.stderr
    assert record.returncode == 0, record_out
    return {"tmp": tmp, "ns": ns, "env": env, "run": run, "record_out": record_out,
            "run_file": tmp / "run" / "run.mcap", "record_file": rec_file}


def test_hcc_run_recording_reads_with_the_mcap_package(recorded_run: dict) -> None:
    rec = read_all(recorded_run["run_file"])
    check_recording(rec, recorder="hcc run", namespace=recorded_run["ns"])
    assert rec["metadata"]["hcc_run"]["mode"] == "realtime"
    assert rec["metadata"]["hcc_recording_end"]["end"] == "finished"
    # The first state of the run is recorded (subscribed before the daemons started).
    assert rec["messages"]["/joint_state"][0]["seq"] == 0
    # The results were derived from it.
    out = recorded_run["tmp"] / "run"
    assert (out / "trajectory.csv").exists() and (out / "metrics.json").exists()


def test_hcc_record_attached_to_a_run_reads_with_the_mcap_package(recorded_run: dict) -> None:
    rec = read_all(recorded_run["record_file"])
    check_recording(rec, recorder="hcc record", namespace=recorded_run["ns"])
    assert "controller is gone" in rec["metadata"]["hcc_recording_end"]["end"]
    assert "lost" in recorded_run["record_out"]


def test_replay_of_the_realtime_run_is_bit_identical(recorded_run: dict) -> None:
    r = hcc("replay", str(recorded_run["run_file"]), env=recorded_run["env"])
    print(r.stdout)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "bit-identical" in r.stdout


def test_sigkill_of_the_recorder_leaves_a_readable_file(tmp_path: pathlib.Path) -> None:
    env = env_with_prefix()
    ns = unique("kill")
    rec_file = tmp_path / "killed.mcap"
    record = start_recorder(ns, rec_file, env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    run = subprocess.Popen(
        [str(binary("hcc")), "run", str(CONFIG), "--duration", "8", "--namespace", ns,
         "--out", str(tmp_path / "run"), "--no-plots", "--quiet"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )
    try:
        # Let it record a few chunks (the file grows once per second), then kill it.
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (
            not rec_file.exists() or rec_file.stat().st_size < 200_000
        ):
            assert record.poll() is None, "the recorder ended early"
            time.sleep(0.1)
        time.sleep(1.5)
        record.send_signal(signal.SIGKILL)
        record.wait(timeout=10)
        run_out, _ = run.communicate(timeout=120)
    finally:
        for p in (record, run):
            if p.poll() is None:
                p.kill()
                p.wait()
    assert run.returncode == 0, run_out

    # The independent reader: messages up to the last complete chunk, then the end of the data.
    counts: dict[str, int] = {}
    error = None
    with open(rec_file, "rb") as f:
        try:
            for _schema, channel, _message in NonSeekingReader(f).iter_messages(
                log_time_order=False
            ):
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
        except (McapError, EOFError, ValueError) as e:
            error = e
    print(f"read {counts} from the killed recording; reader stopped with {error!r}")
    assert counts.get("/joint_state", 0) >= 1000
    assert counts.get("/telemetry", 0) >= 1000

    # hcc plot turns it into results (with the plots).
    out = tmp_path / "plot"
    r = hcc("plot", str(rec_file), "--out", str(out), env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "truncated" in r.stdout
    lines = (out / "trajectory.csv").read_text().splitlines()
    assert len(lines) > 1000
    assert list(out.glob("*.png"))


def test_replay_with_a_changed_gain_names_the_first_difference(
    recorded_run: dict, tmp_path: pathlib.Path
) -> None:
    # The same scenario with K3 changed by one part in a million.
    text = CONFIG.read_text()
    assert "stiffness = 2400.0" in text
    (tmp_path / "changed.toml").write_text(text.replace("stiffness = 2400.0", "stiffness = 2400.0024"))
    (tmp_path / URDF.name).write_bytes(URDF.read_bytes())
    r = hcc("replay", str(recorded_run["run_file"]), "--config", str(tmp_path / "changed.toml"),
            env=recorded_run["env"])
    print(r.stdout)
    assert r.returncode != 0
    assert "differs from the recording at cycle" in r.stdout and "joint" in r.stdout
