"""Many viewers on one project: does every viewer stay within 2 frames of the newest?

    python bench/viewers.py [--viewers 50] [--seconds 30] [--fps 60] [--procs 1]
                            [--server instrumented|plain] [--compression deflate|none]
                            [--warmup 2] [--brief]

A server on a free port with a temp data dir (its built-in 68-point sample project);
--viewers websocket clients (the `websockets` package, asyncio, uvloop when installed)
spread over --procs client processes all open /api/projects/{id}/stream; then one short
control connection sends {"type": "start", "source": "demo", "fps": 60} and leaves, and
the viewers read for --warmup + --seconds. Only the last --seconds count.

Lag of a received frame = (index of the newest frame the server had published when the
viewer received it) - (the received frame's index). The newest published index comes
from the server's own publish times: with `--server instrumented` (default) from a
publish log kept inside the server process; with `--server plain` (exactly `retarget
serve`) from the frames' header timestamps (encode_frame stamps each frame just before
hub.publish) gathered over all viewers. Both use the one machine clock, so no viewer's
view of "newest" is trusted. Latency = receive time - that stamp.

Per viewer: frames received against expected, missing indices (dropped by its one-slot
mailbox), lag max and p99, latency median and p99. The server's RSS (/proc/<pid>/status
VmRSS) and CPU are sampled every second: RSS at start, max, end and its slope over the
last 20 s (MB/min). Each client process reports its CPU use, so a client that could not
keep up (near 100 % of a core) is visible: its late reads would show up as lag.

`--server instrumented` runs the same app as `retarget serve` (create_app + uvicorn.run,
log level info) in a child process, adding only: a wrapper around the hub's publish that
logs (index, time) and the mailboxes' backlog, a 20 ms sampler of every mailbox's backlog,
every websocket transport's write buffer and the event loop's lateness, and a
GET /bench/stats route. Nothing in server/ is changed.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import multiprocessing as mp
import struct
import sys
import time
from array import array
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tqdm import tqdm  # noqa: E402

from bench.stream import (HEADER, ServerProcess, connect, cpu_seconds, fmt, http_json,  # noqa: E402
                          machine, rss_mb, sample_project, serve_command, stats)

SAMPLE_S = 0.02
STALL_MS = 10.0
CLIENT_STALL_MARGIN_S = 0.05


# -- the instrumented server (a child process) -------------------------------------------

def serve_instrumented(port: int, data_dir: str) -> None:
    import weakref

    import uvicorn
    from uvicorn.protocols.websockets.auto import AutoWebSocketsProtocol  # what ws="auto" runs

    from server.app import UVICORN_OPTIONS, create_app

    protocols = weakref.WeakSet()
    cls = AutoWebSocketsProtocol
    original_made = cls.connection_made

    def made(self, transport):
        protocols.add(self)
        return original_made(self, transport)
    cls.connection_made = made

    app = create_app(Path(data_dir))
    hub = app.state.hub
    log_index, log_time = array("I"), array("d")
    stalls, gc_pauses, gc_start = [], [], {}

    def gc_callback(phase, info):  # collector pauses, to tell them from other stalls
        if phase == "start":
            gc_start["t"] = time.perf_counter()
        elif "t" in gc_start:
            gc_pauses.append((time.time(), 1e3 * (time.perf_counter() - gc_start.pop("t")),
                              info["generation"]))
    gc.callbacks.append(gc_callback)
    s = {"publishes": 0, "max_backlog_at_put": 0, "max_backlog_sampled": 0, "max_mailboxes": 0,
         "max_write_buffer": 0, "loop_late_max_ms": 0.0, "samples": 0, "sampler": None}
    publish = hub.publish

    def logged_publish(project_id, frame):
        boxes = hub._viewers.get(project_id, ())
        for box in boxes:
            s["max_backlog_at_put"] = max(s["max_backlog_at_put"], box.backlog)
        log_time.append(time.time())
        log_index.append(struct.unpack_from("<I", frame, 8)[0])
        publish(project_id, frame)
        s["publishes"] += 1

    hub.publish = logged_publish

    async def sampler():
        loop = asyncio.get_running_loop()
        while True:
            t = loop.time()
            await asyncio.sleep(SAMPLE_S)
            late = 1e3 * (loop.time() - t - SAMPLE_S)
            s["loop_late_max_ms"] = max(s["loop_late_max_ms"], late)
            if late > STALL_MS:
                stalls.append((time.time(), late))
            s["samples"] += 1
            for boxes in list(hub._viewers.values()):
                s["max_mailboxes"] = max(s["max_mailboxes"], len(boxes))
                for box in boxes:
                    s["max_backlog_sampled"] = max(s["max_backlog_sampled"], box.backlog)
            for proto in list(protocols):
                transport = getattr(proto, "transport", None)
                if transport is not None and not transport.is_closing():
                    s["max_write_buffer"] = max(s["max_write_buffer"], transport.get_write_buffer_size())

    @app.get("/bench/stats", include_in_schema=False)
    async def bench_stats(reset: bool = False, log: bool = False) -> dict:
        if s["sampler"] is None:
            s["sampler"] = asyncio.get_running_loop().create_task(sampler())
        if reset:
            for key in ("max_backlog_at_put", "max_backlog_sampled", "max_mailboxes",
                        "max_write_buffer", "loop_late_max_ms", "samples"):
                s[key] = 0
        out = {k: v for k, v in s.items() if k != "sampler"}
        out["newest_index"] = log_index[-1] if log_index else None
        out["mailboxes"] = {pid: [[b.delivered, b.dropped, b.backlog] for b in boxes]
                            for pid, boxes in hub._viewers.items()}
        out["websockets"] = len(protocols)
        out["stalls"], out["gc_pauses"] = stalls, gc_pauses
        if log:
            out["log_index"], out["log_time"] = log_index.tolist(), log_time.tolist()
        return out

    uvicorn.run(app, host="127.0.0.1", port=port, log_level="info", **UVICORN_OPTIONS)


def instrumented_command(port: int, data_dir: Path) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--serve-instrumented",
            "--port", str(port), "--data-dir", str(data_dir)]


# -- viewer processes --------------------------------------------------------------------

def viewer_process(proc: int, ids: list[int], url: str, compression, loop_name: str,
                   ready, go, t_end, results) -> None:
    async def read(ws, deadline: float):
        index, sent, received = array("I"), array("d"), array("d")
        try:
            async with asyncio.timeout_at(deadline):
                async for msg in ws:
                    now = time.time()
                    if isinstance(msg, bytes):
                        _, _, _, i, _, _, stamp = HEADER.unpack_from(msg)
                        index.append(i)
                        sent.append(stamp)
                        received.append(now)
        except TimeoutError:
            pass
        return index.tobytes(), sent.tobytes(), received.tobytes()

    async def run():
        sockets = []
        for _ in ids:
            ws = await connect(url, compression).__aenter__()
            hello = json.loads(await ws.recv())
            assert hello["type"] == "hello", hello
            sockets.append(ws)
        ready.put(proc)
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, go.wait)
        deadline = loop.time() + (t_end.value - time.time())
        cpu0, wall0 = time.process_time(), time.time()
        stalls = []
        watch = loop.create_task(watch_loop(stalls))
        data = await asyncio.gather(*(read(ws, deadline) for ws in sockets))
        watch.cancel()
        cpu = (time.process_time() - cpu0) / (time.time() - wall0)
        for ws in sockets:
            await ws.close()
        return data, (cpu, stalls)

    async def watch_loop(stalls):
        """This client loop's lateness over STALL_MS: (wall time, ms)."""
        loop = asyncio.get_running_loop()
        while True:
            t = loop.time()
            await asyncio.sleep(SAMPLE_S)
            late = 1e3 * (loop.time() - t - SAMPLE_S)
            if late > STALL_MS:
                stalls.append((time.time(), late))

    if loop_name == "uvloop":
        import uvloop
        data, cpu = uvloop.run(run())
    else:
        data, cpu = asyncio.run(run())
    results.put((proc, ids, data, cpu))


async def control_start(url: str, fps: float) -> float:
    """Start the demo from a short-lived extra connection; answers when it was sent."""
    async with connect(url, None) as ws:
        await ws.recv()  # hello
        t = time.time()
        await ws.send(json.dumps({"type": "start", "source": "demo", "fps": fps}))
        while True:
            msg = await ws.recv()
            if isinstance(msg, str) and json.loads(msg)["type"] in ("started", "error"):
                assert json.loads(msg)["type"] == "started", msg
                return t


# -- analysis ----------------------------------------------------------------------------

def newest_published(pub_index: np.ndarray, pub_time: np.ndarray):
    """A function t -> index of the newest frame published at or before t."""
    order = np.argsort(pub_time, kind="stable")
    times, newest = pub_time[order], np.maximum.accumulate(pub_index[order].astype(np.int64))

    def at(t):
        k = np.searchsorted(times, t, side="right") - 1
        return np.where(k >= 0, newest[np.maximum(k, 0)], -1)
    return at


def slope_mb_per_min(samples, since: float) -> float:
    t = np.array([a for a, _ in samples if a >= since])
    m = np.array([b for a, b in samples if a >= since])
    if len(t) < 3:
        return float("nan")
    return float(np.polyfit((t - t[0]) / 60.0, m, 1)[0])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--viewers", type=int, default=50)
    p.add_argument("--seconds", type=float, default=30.0, help="measured time (after the warm-up)")
    p.add_argument("--warmup", type=float, default=2.0, help="seconds of streaming not counted")
    p.add_argument("--fps", type=float, default=60.0)
    p.add_argument("--procs", type=int, default=1, help="client processes the viewers are spread over")
    p.add_argument("--server", choices=("instrumented", "plain"), default="instrumented")
    p.add_argument("--compression", choices=("deflate", "none"), default="deflate",
                   help="permessage-deflate offered by the viewers (browsers offer it)")
    p.add_argument("--client-loop", choices=("uvloop", "asyncio"), default=None,
                   help="the viewers' event loop (default: uvloop when installed)")
    p.add_argument("--brief", action="store_true", help="print only the first 5 and the worst 5 viewers' rows")
    p.add_argument("--serve-instrumented", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--port", type=int, help=argparse.SUPPRESS)
    p.add_argument("--data-dir", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.serve_instrumented:
        serve_instrumented(args.port, args.data_dir)
        return 0
    if args.client_loop is None:
        try:
            import uvloop  # noqa: F401
            args.client_loop = "uvloop"
        except ImportError:
            args.client_loop = "asyncio"
    compression = None if args.compression == "none" else "deflate"
    instrumented = args.server == "instrumented"
    print(f"machine: {machine()}; {args.viewers} viewers in "
          f"{args.procs} client process(es) ({args.client_loop}), {args.fps:g} fps, "
          f"{args.warmup:g} s warm-up + {args.seconds:g} s measured, compression {args.compression}, "
          f"server {'instrumented (create_app + uvicorn.run)' if instrumented else '`retarget serve`'}")

    command = instrumented_command if instrumented else serve_command
    ctx = mp.get_context("spawn")
    with ServerProcess(command=command) as server:
        project = sample_project(server.url)
        url = f"{server.ws_url}/api/projects/{project}/stream"
        if instrumented:
            http_json(server.url + "/bench/stats")  # starts the sampler
        rss_idle = rss_mb(server.pid)
        ready, results, go, t_end = ctx.Queue(), ctx.Queue(), ctx.Event(), ctx.Value("d", 0.0)
        groups = [list(range(args.viewers))[k::args.procs] for k in range(args.procs)]
        procs = [ctx.Process(target=viewer_process, daemon=True,
                             args=(k, g, url, compression, args.client_loop, ready, go, t_end, results))
                 for k, g in enumerate(groups)]
        t_connect = time.perf_counter()
        for proc in procs:
            proc.start()
        for _ in procs:
            ready.get(timeout=120)
        connect_s = time.perf_counter() - t_connect
        rss_connected = rss_mb(server.pid)
        total = args.warmup + args.seconds
        t_end.value = time.time() + total + 0.5
        go.set()
        t_start_sent = asyncio.run(control_start(url, args.fps))
        t_measure = t_start_sent + args.warmup
        t_stop = t_measure + args.seconds

        samples, cpu_samples = [], []
        server_stats_reset = False
        bar = tqdm(total=int(round(total)), desc="viewers", unit="s", file=sys.stderr)
        next_tick = time.time()
        while time.time() < t_end.value:
            now = time.time()
            samples.append((now, rss_mb(server.pid)))
            cpu_samples.append((now, cpu_seconds(server.pid)))
            if instrumented and not server_stats_reset and now >= t_measure:
                http_json(server.url + "/bench/stats?reset=true")  # the warm-up's maxima don't count
                server_stats_reset = True
            bar.n = min(bar.total, int(now - t_start_sent))
            bar.refresh()
            next_tick += 1.0
            time.sleep(max(0.0, next_tick - time.time()))
        bar.close()
        server_stats = http_json(server.url + "/bench/stats?log=true") if instrumented else None
        collected = [results.get(timeout=60) for _ in procs]
        for proc in procs:
            proc.join(10)
        time.sleep(1.0)
        rss_after = rss_mb(server.pid)
        after_stats = http_json(server.url + "/bench/stats") if instrumented else None

    # -- figures --
    viewers = {}
    client_cpu, client_stalls, stall_spans, proc_of = {}, [], [], {}
    for proc, ids, data, (cpu, stalls) in collected:
        client_cpu[proc] = cpu
        stall_spans += [(proc, t - ms / 1e3 - SAMPLE_S, t + CLIENT_STALL_MARGIN_S) for t, ms in stalls]
        client_stalls += [(t - t_start_sent, ms) for t, ms in stalls if t_measure <= t <= t_stop]
        for vid, (ib, sb, rb) in zip(ids, data):
            proc_of[vid] = proc
            viewers[vid] = (np.frombuffer(ib, dtype=np.uint32).astype(np.int64),
                            np.frombuffer(sb), np.frombuffer(rb))
    if instrumented:
        pub_index = np.array(server_stats["log_index"], dtype=np.int64)
        pub_time = np.array(server_stats["log_time"])
        source_of_newest = "the server's publish log"
    else:
        pub_index, first = np.unique(np.concatenate([v[0] for v in viewers.values()]), return_index=True)
        pub_time = np.concatenate([v[1] for v in viewers.values()])[first]  # one stamp per frame
        source_of_newest = "frame header stamps over all viewers"
    newest = newest_published(pub_index, pub_time)
    published_in_window = int(np.sum((pub_time >= t_measure) & (pub_time < t_stop)))

    rows = []
    for vid in sorted(viewers):
        index, sent, received = viewers[vid]
        w = (received >= t_measure) & (received < t_stop)
        idx, rcv, snt = index[w], received[w], sent[w]
        lag = newest(rcv) - idx
        in_stall = np.zeros(len(rcv), bool)
        for proc, a, b in stall_spans:
            if proc == proc_of[vid]:
                in_stall |= (rcv >= a) & (rcv <= b)
        missing = int((idx[-1] - idx[0] + 1) - len(np.unique(idx))) if len(idx) else 0
        rows.append({"viewer": vid, "frames": int(w.sum()), "missing": missing,
                     "lag_max": int(lag.max()) if len(lag) else -1,
                     "lag_p99": float(np.percentile(lag, 99)) if len(lag) else float("nan"),
                     "lag_hist": np.bincount(np.clip(lag, 0, 10), minlength=11) if len(lag) else np.zeros(11),
                     "lat_med": 1e3 * float(np.median(rcv - snt)) if len(rcv) else float("nan"),
                     "lat_p99": 1e3 * float(np.percentile(rcv - snt, 99)) if len(rcv) else float("nan"),
                     "latency": rcv - snt, "late_times": rcv[lag > 2],
                     "lag_clean": lag[~in_stall], "n_stalled": int(in_stall.sum())})
    expected = args.seconds * args.fps
    print(f"\nconnect {args.viewers} viewers: {connect_s:.2f} s; frames published by the server in the "
          f"{args.seconds:g} s window: {published_in_window} (expected {expected:.0f}); "
          f"'newest' from {source_of_newest}")

    header = (f"{'viewer':>6} {'frames':>7} {'expect':>7} {'missing':>7} {'lag max':>7} "
              f"{'lag p99':>7} {'lat med ms':>10} {'lat p99 ms':>10}")

    def row(r):
        return (f"{r['viewer']:>6} {r['frames']:>7} {expected:>7.0f} {r['missing']:>7} {r['lag_max']:>7} "
                f"{r['lag_p99']:>7.1f} {r['lat_med']:>10.3f} {r['lat_p99']:>10.3f}")

    print(header)
    if not args.brief or len(rows) <= 12:
        shown = rows
    else:
        worst = sorted(rows, key=lambda r: (r["lag_max"], r["lag_p99"], r["lat_p99"]))[-5:]
        shown = rows[:5] + [None] + worst
    for r in shown:
        print(row(r) if r is not None else f"{'...':>6}   (worst 5 by lag:)")
    frames = np.array([r["frames"] for r in rows])
    lag_max = np.array([r["lag_max"] for r in rows])
    lag_p99 = np.array([r["lag_p99"] for r in rows])
    hist = np.sum([r["lag_hist"] for r in rows], axis=0)
    all_lat = 1e3 * np.concatenate([r["latency"] for r in rows])
    print(f"over {len(rows)} viewers: frames received min {frames.min()} / median {np.median(frames):.0f} / "
          f"max {frames.max()} of {expected:.0f}; missing total {sum(r['missing'] for r in rows)}")
    print(f"  lag (frames behind the newest published): max over viewers {lag_max.max()}, "
          f"p99 median {np.median(lag_p99):.1f} / worst {lag_p99.max():.1f}; viewers with max lag > 2: "
          f"{int(np.sum(lag_max > 2))} of {len(rows)}")
    shares = ", ".join(f"{k}{'+' if k == 10 else ''}: {100 * hist[k] / hist.sum():.3f} %"
                       for k in range(11) if hist[k])
    print(f"  lag distribution over all received frames: {shares}")
    print(f"  send -> receive latency over all viewers: {fmt(stats(all_lat))}")
    print(f"  client CPU per process (share of one core): "
          + ", ".join(f"#{k}: {100 * c:.0f} %" for k, c in sorted(client_cpu.items())))
    print(f"  client event loop stalls over {STALL_MS:g} ms in the window: {len(client_stalls)}"
          + (f", longest {max(ms for _, ms in client_stalls):.0f} ms; (s since start: ms) "
             + ", ".join(f"{t:.1f}: {ms:.0f}" for t, ms in sorted(client_stalls)[:12]) if client_stalls else ""))
    clean = np.concatenate([r["lag_clean"] for r in rows])
    print(f"  lag leaving out receives during or within {1e3 * CLIENT_STALL_MARGIN_S:.0f} ms after a stall "
          f"of the viewer's own client process ({sum(r['n_stalled'] for r in rows)} of {len(all_lat)} "
          f"receives left out): max {clean.max() if len(clean) else -1}, p99 "
          f"{np.percentile(clean, 99) if len(clean) else float('nan'):.1f}, receives with lag > 2: "
          f"{int(np.sum(clean > 2))}")
    late = sorted({round(float(t) - t_start_sent, 1) for r in rows for t in r["late_times"]})
    print(f"  receives with lag > 2: {sum(len(r['late_times']) for r in rows)}"
          + (f", at (s since start) {', '.join(f'{t:.1f}' for t in late[:20])}" if late else ""))
    w = (pub_time >= t_measure) & (pub_time < t_stop)
    order = np.argsort(pub_time[w])
    gaps = np.diff(pub_time[w][order])
    print(f"  source publish interval: {fmt(stats(1e3 * gaps))}; catch-up publishes (under half a frame "
          f"after the previous, the source running behind schedule): {int(np.sum(gaps < 0.5 / args.fps))}")

    t = np.array([a for a, _ in samples])
    mb = np.array([b for _, b in samples])
    in_window = (t >= t_measure) & (t <= t_stop + 0.5)
    cpu_t = np.array([a for a, _ in cpu_samples])
    cpu_s = np.array([b for _, b in cpu_samples])
    server_cpu = (cpu_s[-1] - cpu_s[np.argmax(cpu_t >= t_measure)]) / (cpu_t[-1] - cpu_t[np.argmax(cpu_t >= t_measure)])
    print(f"server RSS (MiB): idle {rss_idle:.1f}, {args.viewers} connected {rss_connected:.1f}, "
          f"window start {mb[in_window][0]:.1f}, max {mb[in_window].max():.1f}, end {mb[in_window][-1]:.1f}, "
          f"after the viewers left {rss_after:.1f}; slope over the last 20 s "
          f"{slope_mb_per_min(samples, t_stop - 20):+.2f} MB/min, over the whole window "
          f"{slope_mb_per_min(samples, t_measure):+.2f} MB/min ({int(in_window.sum())} samples)")
    print(f"server CPU during the window: {100 * server_cpu:.0f} % of one core")
    if instrumented:
        boxes = next(iter(server_stats["mailboxes"].values()), [])
        dropped = [b[1] for b in boxes]
        print(f"server hub (in-process, measured window): mailboxes {server_stats['max_mailboxes']} "
              f"(max seen), backlog max {server_stats['max_backlog_sampled']} over "
              f"{server_stats['samples']} samples every {1e3 * SAMPLE_S:.0f} ms, backlog found at put "
              f"max {server_stats['max_backlog_at_put']} (1 = the previous frame was still untaken "
              f"and was dropped); dropped per mailbox over the whole run: "
              f"max {max(dropped) if dropped else 0}, total {sum(dropped)}")
        print(f"  websocket transport write buffer max {server_stats['max_write_buffer']} bytes; "
              f"event loop lateness max {server_stats['loop_late_max_ms']:.1f} ms; after the viewers "
              f"left: {sum(len(v) for v in after_stats['mailboxes'].values())} mailboxes, "
              f"{after_stats['publishes'] - server_stats['publishes']} more publishes")
        stalls = [(t - t_start_sent, ms) for t, ms in server_stats["stalls"] if t_measure <= t <= t_stop]
        pauses = [(t - t_start_sent, ms, g) for t, ms, g in server_stats["gc_pauses"] if t_measure <= t <= t_stop]
        print(f"  event loop stalls over {STALL_MS:g} ms in the window: {len(stalls)}"
              + (" (s since start: ms) " + ", ".join(f"{t:.1f}: {ms:.0f}" for t, ms in stalls[:12]) if stalls else ""))
        big = [x for x in pauses if x[1] > 5]
        print(f"  garbage collections in the window: {len(pauses)}, total {sum(x[1] for x in pauses):.1f} ms, "
              f"longest {max((x[1] for x in pauses), default=0):.1f} ms"
              + ("; over 5 ms (s: ms, generation) " + ", ".join(f"{t:.1f}: {ms:.0f} g{g}" for t, ms, g in big[:12])
                 if big else ""))
    print(f"machine at the end: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
