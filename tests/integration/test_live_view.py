"""Watching a secure real-time run live: ``foresight demo --live`` (the executor serves the scene it logs) and
``foresight view`` beside it (a separate process, the read-only observer under mutual TLS). A client speaking
Foxglove's WebSocket protocol on each gets every scene channel's messages, each decoding with the schema the
server advertised; both servers stop with the run."""

from __future__ import annotations

import base64
import json
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from services.processes import free_port
from shared.foxglove.client import FoxgloveClient, Received
from shared.foxglove.decode import SchemaDecoder
from shared.foxglove.stream import SCHEMAS
from shared.library import save_library
from shared.security.acl import ROLES
from shared.security.certificates import init_security_dir
from shared.synthetic import generate_library


def watch(url: str, got: list[Received], channels: dict[str, dict], errors: list[BaseException]) -> None:
    """Subscribe to every channel at ``url`` and collect messages until the server goes away."""
    try:
        with FoxgloveClient(url, timeout_s=240) as client:
            channels.update({ch["topic"]: ch for ch in client.channels.values()})
            client.subscribe()
            while not client.closed:
                got += client.receive(0.5)
    except BaseException as exc:  # noqa: BLE001 - reported by the test
        errors.append(exc)


def check(got: list[Received], channels: dict[str, dict]) -> None:
    counts = {t: sum(r.topic == t for r in got) for t in SCHEMAS if t != "/viz/keypoints"}  # a recording: no sensor
    assert set(channels) == set(SCHEMAS) and all(n > 0 for n in counts.values()), counts
    decoder = SchemaDecoder()
    for r in got:
        ch = channels[r.topic]
        schema = base64.b64decode(ch["schema"]) if ch["schemaEncoding"] == "protobuf" else ch["schema"].encode()
        decoder.decode(r.topic, ch["schemaName"], ch["schemaEncoding"], schema, r.data)


@pytest.mark.slow
def test_clients_see_every_scene_channel_of_a_secure_realtime_run(tmp_path: Path) -> None:
    lib = tmp_path / "lib.npz"
    save_library(generate_library(8, 6, seed=3), lib)
    sec = tmp_path / "sec"
    init_security_dir(sec, ROLES)
    router, live, view = free_port(), free_port(), free_port()
    demo = subprocess.Popen(
        [sys.executable, "-m", "tools", "demo", "--mode", "realtime", "--steps", "16", "--no-finish",
         "--library", str(lib), "--components", "4", "--models-dir", str(tmp_path / "models"),
         "--run-dir", str(tmp_path / "run"),
         "--security", str(sec), "--port", str(router), "--live", str(live), "--timeout", "300"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)
    viewer = subprocess.Popen(
        [sys.executable, "-m", "tools", "view", "--port", str(view), "--connect", f"tls/127.0.0.1:{router}",
         "--security", str(sec), "--log-level", "INFO"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)
    results: dict[str, tuple[list, dict, list]] = {"live": ([], {}, []), "view": ([], {}, [])}
    threads = [threading.Thread(target=watch, args=(f"ws://127.0.0.1:{port}", *results[name]), daemon=True)
               for name, port in (("live", live), ("view", view))]
    try:
        for t in threads:
            t.start()
        out, _ = demo.communicate(timeout=400)
        threads[0].join(30)  # the executor's server went with the run
        viewer.terminate()  # Ctrl-C / SIGTERM: the view stops, its server with it
        view_out, _ = viewer.communicate(timeout=30)
        threads[1].join(30)
    finally:
        for proc in (demo, viewer):
            if proc.poll() is None:
                proc.kill()
                proc.communicate(timeout=30)
    assert demo.returncode == 0, out[-3000:]
    assert f"watch live at ws://127.0.0.1:{live}" in out
    assert viewer.returncode == 0 and "view: stopped" in view_out and "Traceback" not in view_out, view_out[-3000:]
    assert not any(t.is_alive() for t in threads)
    for name, (got, channels, errors) in results.items():
        assert not errors, (name, errors)
        check(got, channels)
    # the live table's rows are the summary's plans (the log's), but for those the executor never adopted (overtaken
    # by a newer plan, or made as the run ended), which the demo names (an extra row, unexplained, before)
    rows = [ln for ln in out.splitlines() if re.match(r"^ *\d+ +\d+\.\d\d  ", ln)]
    said = re.search(r"(?:(\d+) rows above were|one row above was a) plans? the executor never adopted", out)
    unexecuted = 0 if said is None else int(said.group(1) or 1)
    (mcap,) = (tmp_path / "run").rglob("*.mcap")
    table = subprocess.run([sys.executable, "-m", "tools", "log", "table", "--json", str(mcap)], capture_output=True,
                           text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert table.returncode == 0, table.stderr[-3000:]
    assert len(rows) - unexecuted == len(json.loads(table.stdout)["steps"]), out[-3000:]
