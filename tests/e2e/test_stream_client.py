"""web/static/js/StreamClient.js against a real server in Chromium: hello and frames,
stats, reconnecting with the last start re-sent after the server goes away, and no
reconnect after a policy close (1008) or close()."""

from __future__ import annotations


import pytest
from tests.waits import scaled_ms

# The page is written into a document of the server's origin (a JSON route) rather than
# served by page.route: Chromium treats a route-fulfilled page as a public address and
# refuses its WebSocket to 127.0.0.1 (local network access checks).
PAGE = """<!doctype html><meta charset="utf-8"><title>stream check</title>
<script type="module">
import { StreamClient } from '/static/js/net/StreamClient.js';

window.open_ = ( projectId ) => {
	const client = new StreamClient( projectId );
	const log = { statuses: [], hello: null, messages: [], frames: 0, lastFrame: null };
	client.addEventListener( 'status', ( e ) => log.statuses.push( e.detail ) );
	client.addEventListener( 'hello', ( e ) => { log.hello = e.detail; } );
	client.addEventListener( 'message', ( e ) => log.messages.push( e.detail ) );
	client.addEventListener( 'frame', ( e ) => {
		log.frames ++;
		log.lastFrame = { frameIndex: e.detail.frameIndex, count: e.detail.count, n: e.detail.displacements.length };
		client.markApplied( e.detail );
	} );
	window.client = client;
	window.log = log;
	return client;
};
window.ready = true;
</script>
"""




@pytest.fixture
def client_page(server, page):
    page.goto(server.url + "/api/layouts")
    page.set_content(PAGE)
    page.wait_for_function("window.ready === true")
    return page


def _sample_id(server) -> str:
    return next(p["id"] for p in server.api("GET", "/api/projects") if p["settings"].get("sample"))


def _log(page) -> dict:
    return page.evaluate("JSON.parse(JSON.stringify(log))")


def test_frames_and_stats(server, client_page):
    page = client_page
    project_id = _sample_id(server)
    page.evaluate("(id) => { const c = open_(id); c.send({type: 'start', source: 'demo', fps: 30}); c.connect(); }", project_id)
    page.wait_for_function("log.frames >= 45", timeout=scaled_ms(20_000))
    log = _log(page)
    assert [s["state"] for s in log["statuses"]] == ["connecting", "open"]
    assert log["hello"]["project"] == project_id and log["hello"]["n_points"] == 68
    assert {"type": "started", "source": "demo", "fps": 30.0, "recording": False, "drive": "points"} in log["messages"]
    assert log["lastFrame"]["count"] == 68 and log["lastFrame"]["n"] == 3 * 68

    # 30 fps over the last second; a loaded machine can stall the page for a moment, after
    # which the rate comes back (a broken count would never be in range)
    page.wait_for_function("client.stats.fps >= 15 && client.stats.fps <= 45", timeout=scaled_ms(10_000))
    stats = page.evaluate("client.stats")
    assert stats["frames"] >= 45
    median, p99 = stats["latencyMs"]["median"], stats["latencyMs"]["p99"]
    # same machine: the clocks agree; the page's Date.now() counts whole milliseconds, so a
    # frame applied within the millisecond it was sent can read up to 1 ms below zero
    assert -1 < median <= p99 < 2000, stats

    page.evaluate("client.close()")
    assert page.evaluate("client.state") == "closed"
    frames = _log(page)["frames"]
    page.wait_for_timeout(300)
    assert _log(page)["frames"] == frames  # nothing arrives after close()


def test_reconnects_and_restarts_the_demo(server, client_page):
    page = client_page
    project_id = _sample_id(server)
    page.evaluate("(id) => { const c = open_(id); c.connect(); c.send({type: 'start', source: 'demo', fps: 30}); }", project_id)
    page.wait_for_function("log.frames >= 5", timeout=scaled_ms(20_000))

    server.restart()  # same port and data: the page sees the connection drop
    page.wait_for_function("log.statuses.some((s) => s.state === 'reconnecting')", timeout=scaled_ms(20_000))
    page.wait_for_function("log.statuses.at(-1).state === 'open'", timeout=scaled_ms(30_000))
    # the new server has no source until the client re-sends its start
    frames = _log(page)["frames"]
    page.wait_for_function(f"log.frames >= {frames + 10}", timeout=scaled_ms(20_000))
    assert sum(m.get("type") == "started" for m in _log(page)["messages"]) == 2

    page.evaluate("client.close()")
    # the failed attempts while the server was down are expected console errors
    page.console_errors[:] = [e for e in page.console_errors if "WebSocket connection to" not in e]


def test_policy_close_does_not_reconnect(server, client_page):
    page = client_page
    project_id = server.api("POST", "/api/projects", {"name": "no landmarks"})["id"]
    page.evaluate("(id) => open_(id).connect()", project_id)
    page.wait_for_function("log.statuses.at(-1).state === 'closed'", timeout=scaled_ms(20_000))
    page.wait_for_timeout(1000)  # longer than the first backoff steps
    statuses = _log(page)["statuses"]
    assert [s["state"] for s in statuses] == ["connecting", "open", "closed"], statuses
    assert "landmarks" in statuses[-1]["reason"] or "mesh" in statuses[-1]["reason"]
