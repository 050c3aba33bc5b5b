"""``gait-estimator dashboard``: the page's state logic and command checks, then the real thing: a
real estimator_node and the dashboard over loopback DDS (ROS_DOMAIN_IDs 111, 114), the bundled
Multispeed recording streamed in, the page opened in headless Chromium (Debian's chromium and
chromium-driver; ``make test`` installs them) and checked for what a person sees."""

from __future__ import annotations

import asyncio
import json
import math
import os
import threading
import time

import numpy as np
import pytest
from browser import chromium, have_browser

from gait_estimator.dashboard.commands import CommandRefused, parse_command
from gait_estimator.dashboard.state import STATES, estimate_view, gait_state
from gait_estimator.io.outputs import estimate_names

DOMAIN = 111
DOMAIN_REFUSALS = 114
TOKEN = "test-token-1234"


# -- the state logic (before and after the node sends a ``state`` key)


@pytest.mark.parametrize(("values", "state"), [
    ({"ready": 0.0}, "not_ready"),
    ({"ready": 1.0}, "not_ready"),  # no state key: nothing trusted
    ({"ready": 1.0, "state": 0.0}, "not_ready"),
    ({"ready": 1.0, "state": 1.0}, "walking"),
    ({"ready": 1.0, "state": 2.0}, "stand"),
    ({"ready": 1.0, "state": 3.0}, "unknown"),
    ({"ready": 1.0, "state": 7.0}, "not_ready"),
    ({"ready": 1.0, "state": math.nan}, "not_ready"),
])
def test_gait_state(values, state):
    assert gait_state(values) == state


def test_estimate_view_names_the_mode_and_hides_a_phase_not_ready():
    names = [*estimate_names(["Slow", "Fast"]), "state"]
    values = dict.fromkeys(names, 0.0)
    values.update({"mode_index": 1.0, "phase": 0.25, "ready": 1.0, "sse/Slow": 9.0, "sse/Fast": 2.0,
                   "phase_rate": math.nan, "state": 1.0})
    view = estimate_view(names, [values[k] for k in names])
    assert (view["state"], view["mode"], view["phase"], view["phase_rate"]) == ("walking", "Fast", 0.25, None)
    assert view["sse"] == [["Slow", 9.0], ["Fast", 2.0]]
    values.update(state=2.0, phase=0.3)
    view = estimate_view(names, [values[k] for k in names])
    assert (view["mode"], view["phase"]) == ("stand", None)  # a phase only while walking
    values.update(state=0.0, ready=0.0)
    view = estimate_view(names, [values[k] for k in names])
    assert (view["state"], view["mode"], view["phase"]) == ("not_ready", None, None)
    assert set(STATES) == {"not_ready", "walking", "stand", "unknown"}


@pytest.mark.parametrize(("text", "why"), [
    ("garbage", "not JSON"),
    (b"\x00\x01", "binary"),
    ("[1, 2]", "unknown op"),
    ('{"op": "rm -rf"}', "unknown op"),
    ('{"op": "save", "path": "/etc/passwd"}', "unexpected field"),
    ('{"op": "teach", "mode": "Slow", "strides": 2}', "3..100"),
    ('{"op": "teach", "mode": "Slow", "strides": true}', "3..100"),
    ('{"op": "teach", "mode": " Slow", "strides": 5}', "mode must be"),
    ('{"op": "teach", "mode": "a\\nb", "strides": 5}', "mode must be"),
    ('{"op": "teach", "mode": "stand", "strides": 5}', "mode must be"),
    ('{"op": "teach", "mode": "' + "x" * 2000 + '", "strides": 5}', "longer than"),
    ("[" * 500 + "]" * 500, "unknown op"),
])
def test_hostile_commands_are_refused(text, why):
    with pytest.raises(CommandRefused, match=why):
        parse_command(text)


def test_commands_parse():
    assert parse_command('{"op": "teach", "mode": "Ramp_up", "strides": 8}').strides == 8
    assert parse_command('{"op": "cancel"}').op == "cancel"
    assert parse_command('{"op": "save"}').op == "save"


def test_a_non_loopback_host_always_gets_a_token():
    from gait_estimator.cli.dashboard_command import dashboard_token
    from gait_estimator.core.errors import GaitEstimatorError
    from gait_estimator.dashboard.server import TOKEN_ENV, is_loopback

    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.20") and not is_loopback("leg.local")
    assert dashboard_token("127.0.0.1", None, {}) is None
    made = {dashboard_token("0.0.0.0", None, {}) for _ in range(3)}
    assert len(made) == 3 and all(t and len(t) >= 20 for t in made)
    assert dashboard_token("0.0.0.0", None, {TOKEN_ENV: "from-the-env"}) == "from-the-env"
    assert dashboard_token("127.0.0.1", "given-token", {TOKEN_ENV: "from-the-env"}) == "given-token"
    with pytest.raises(GaitEstimatorError, match="at least 8"):
        dashboard_token("0.0.0.0", "short", {})


# -- the real thing


def _require_browser() -> None:
    if not have_browser():
        if os.environ.get("GAIT_REQUIRE_BROWSER"):
            pytest.fail("/usr/bin/chromedriver missing: make browser installs Debian's chromium and chromium-driver")
        pytest.skip("/usr/bin/chromedriver missing (make browser installs it)")


CHART_PIXELS_JS = """
const c = document.querySelector('#chart canvas');
if (!c) return -1;
const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
let n = 0;
for (let i = 0; i < d.length; i += 4) if (d[i+3] > 0 && d[i] > 150 && d[i+1] < 90 && d[i+2] < 90) n++;  // right_thigh red
return n;
"""


def _text(driver, element_id: str) -> str:
    return driver.execute_script(f"return document.getElementById('{element_id}').textContent")


def _until(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"not within {timeout_s:g} s: {what}")


def _http_status(url: str, headers: dict[str, str] | None = None) -> int:
    import aiohttp

    async def go() -> int:
        async with aiohttp.ClientSession() as s, s.get(url, headers=headers) as r:
            return r.status

    return asyncio.run(go())


def _socket_status(url: str, headers: dict[str, str] | None = None) -> int:
    import aiohttp

    async def go() -> int:
        async with aiohttp.ClientSession() as s:
            try:
                async with s.ws_connect(url, headers=headers):
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    return asyncio.run(go())


def test_page_follows_the_node_and_teaches_it(multispeed_csv, tmp_path):
    _require_browser()
    with chromium() as driver:
        _check_page(driver, multispeed_csv, tmp_path)


def _check_page(driver, multispeed_csv, tmp_path) -> None:
    from gait_estimator.dashboard.process import start_dashboard
    from gait_estimator.io.readers import read_recording
    from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command, use_local_ros

    env = local_ros_environment(DOMAIN)
    use_local_ros(DOMAIN)
    dash, url = start_dashboard(["--port", "0", "--domain-id", str(DOMAIN), "--token", TOKEN], env)
    node = client = None
    try:
        assert f"?token={TOKEN}" in url
        base = url.split("?")[0]
        # a missing or wrong token: the page and the socket are refused, in the browser too
        driver.get(base)
        assert "401" in driver.find_element("tag name", "body").text
        driver.get(base + "?token=wrong-token-000")
        assert "403" in driver.find_element("tag name", "body").text
        ws = base.replace("http", "ws") + "ws"
        assert _socket_status(ws) == 401
        assert _socket_status(ws + "?token=wrong-token-000") == 403
        assert _socket_status(ws + f"?token={TOKEN}", {"Origin": "http://evil.example"}) == 403

        # the page before the node exists says so
        driver.get(url)
        _until(lambda: "waiting for /estimator_node" in _text(driver, "link"), 15, "the page waits for the node")

        library = tmp_path / "wearer.yaml"
        node = NodeProcess(node_command(["-p", "kernels:=able_bodied", "-p", f"adapted_library_path:={library}"]), env)
        client = EstimatorClient(DOMAIN, outputs=("estimate", "mode"), reliable=True)
        assert client.wait_for_node(timeout_s=30.0), node.output()
        _until(lambda: "no estimates" in _text(driver, "link"), 15, "the page: node up, no input yet")
        assert _text(driver, "state") == "not ready"
        assert driver.find_element("id", "state-box").get_attribute("class") == "state not_ready"
        rec = read_recording(multispeed_csv, rate_hz=230.0).slice(4600, 14500)
        stamps = 1_700_000_000 * 10**9 + np.round((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64)
        streamer = threading.Thread(target=client.stream, args=(np.radians(rec.angles_deg), stamps, 2.5 * 230.0))
        streamer.start()

        # the mode follows the recording (Slow -> Med -> Fast in these samples), large and coloured
        _until(lambda: "live" in driver.find_element("id", "link").get_attribute("class"), 20, "the page goes live")
        seen: list[str] = []
        deadline = time.monotonic() + 25
        while time.monotonic() < deadline and "Fast" not in seen:
            mode = _text(driver, "mode")
            if mode != "–" and (not seen or seen[-1] != mode):
                seen.append(mode)
            time.sleep(0.1)
        published = [m for i, m in enumerate(client.received.modes) if i == 0 or client.received.modes[i - 1] != m]
        assert {"Med", "Fast"} <= set(seen), (seen, published)
        it = iter(published)
        assert all(m in it for m in seen), f"page modes {seen} not in the order the node published {published}"
        assert driver.find_element("id", "state-box").get_attribute("class") == "state walking"
        assert _text(driver, "state") == "walking"
        # the chart draws the stride and the kernel: points in the data, red pixels on the canvas
        assert driver.execute_script("return window.gaitDashboard.points") > 100
        assert driver.execute_script(CHART_PIXELS_JS) > 200
        assert driver.execute_script("return window.gaitDashboard.kernels.Fast.samples.length") > 100
        frames = driver.execute_script("return window.gaitDashboard.frames")
        time.sleep(2.0)
        rate = (driver.execute_script("return window.gaitDashboard.frames") - frames) / 2.0
        assert rate >= 20, f"{rate} page updates per second"
        assert len(driver.find_elements("css selector", "#errors .bar-row")) == 7

        # teaching from the page adds a mode to the running node
        driver.find_element("id", "teach-mode").send_keys("Clinic")
        strides = driver.find_element("id", "teach-strides")
        strides.clear()
        strides.send_keys("3")
        driver.find_element("id", "teach-start").click()
        _until(lambda: _text(driver, "teach-progress").startswith("Clinic "), 10, "teaching progress on the page")
        _until(lambda: "Clinic" in _text(driver, "teach-result"), 30, "the new kernel's summary on the page")
        assert _until(lambda: any(n == "sse/Clinic" for n in client.received.estimate_names) or
                      "Clinic" in _text(driver, "errors"), 10, "the node matches Clinic")
        _until(lambda: "Clinic" in _text(driver, "errors"), 10, "Clinic among the page's error bars")
        driver.find_element("id", "teach-save").click()
        _until(lambda: str(library) in _text(driver, "reply"), 30, "the library saved")
        assert library.exists() and "Clinic" in library.read_text()
        streamer.join(timeout=60)

        # the node goes away: the page says so; it comes back (restarted): the page follows it again
        node.stop()
        _until(lambda: "gone" in _text(driver, "link"), 15, "the page reports the node gone")
        node.close()
        node = NodeProcess(node_command(["-p", "kernels:=able_bodied"]), env)
        assert client.wait_for_node(timeout_s=30.0), node.output()
        client.stream(np.radians(rec.angles_deg[:1500]), stamps[:1500] + 10**12, 2.5 * 230.0)
        _until(lambda: "live" in driver.find_element("id", "link").get_attribute("class"), 15, "live again")
        _until(lambda: _text(driver, "mode") in ("Slow", "Med", "Fast"), 10, "a mode after the restart")
        out = dash.output()
        assert "refused" in out and "wrong token" in out and "Traceback" not in out, out
    finally:
        if client is not None:
            client.close()
        if node is not None:
            node.close()
        dash.close()


def test_socket_refusals_never_reach_a_node_nor_stop_the_dashboard():
    """--read-only refuses teaching; a flood is refused; an oversized message closes that socket
    only; the dashboard answers the next page, and logs each refusal."""
    import aiohttp

    from gait_estimator.dashboard.process import start_dashboard
    from gait_estimator.dashboard.server import MAX_SOCKETS
    from gait_estimator.ros.node_client import local_ros_environment

    dash, url = start_dashboard(["--port", "0", "--domain-id", str(DOMAIN_REFUSALS), "--read-only"],
                                local_ros_environment(DOMAIN_REFUSALS))
    ws_url = url.replace("http", "ws") + "ws"

    async def replies(messages: list[str]) -> tuple[dict, list[str]]:
        async with aiohttp.ClientSession() as s, s.ws_connect(ws_url) as ws:
            hello = await ws.receive_json()
            for m in messages:
                await ws.send_str(m)
            texts: list[str] = []
            while len(texts) < len(messages):
                msg = await ws.receive(timeout=10)
                if msg.type != aiohttp.WSMsgType.TEXT:
                    texts.append(f"closed {msg.type.name}")
                    break
                if (m := json.loads(msg.data))["type"] == "reply":
                    texts.append(m["text"])
            return hello, texts

    try:
        hello, texts = asyncio.run(replies([json.dumps({"op": "teach", "mode": "Slow", "strides": 5})]))
        assert hello["read_only"] is True
        assert texts == ["refused: read-only dashboard"]
        _, texts = asyncio.run(replies(['{"op": "cancel"}'] * 12))
        assert texts.count("refused: too many messages (at most 5 a second)") >= 5
        _, texts = asyncio.run(replies(["x" * 5000]))
        assert texts and texts[0].startswith("closed")
        hello, _ = asyncio.run(replies([]))
        assert hello["type"] == "hello"
        # DNS rebinding: another site's name resolved to 127.0.0.1 reaches neither page nor socket
        rebound = {"Host": f"evil.example:{url.rsplit(':', 1)[1].strip('/')}"}
        assert _socket_status(ws_url, {**rebound, "Origin": f"http://{rebound['Host']}"}) == 403
        assert _http_status(url, rebound) == 403 and _http_status(url) == 200

        async def many() -> list[int]:  # at most MAX_SOCKETS pages at once
            async with aiohttp.ClientSession() as s:
                opened, statuses = [], []
                for _ in range(MAX_SOCKETS + 1):
                    try:
                        opened.append(await s.ws_connect(ws_url))
                        statuses.append(101)
                    except aiohttp.WSServerHandshakeError as exc:
                        statuses.append(exc.status)
                for ws in opened:
                    await ws.close()
                return statuses

        assert asyncio.run(many()) == [101] * MAX_SOCKETS + [503]
        out = dash.output()
        assert "read-only dashboard" in out and "too many messages" in out and "socket closed" in out, out
        assert "Traceback" not in out
    finally:
        dash.close()
