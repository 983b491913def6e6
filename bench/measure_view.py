#!/usr/bin/env python3
"""Measures the viewers as a person uses them: frames/s while the camera moves, input to frame
latency, time to sharpen after the camera stops.

    bench/measure_view.py window -- target/dist/megaray view SCENE --mem 2G --res 640x480
    bench/measure_view.py serve  -- target/dist/megaray serve SCENE --mem 2G

`window` needs an X display (Xvfb) and xdotool; `serve` needs Chromium (driven headless
through its DevTools protocol, the page's viewport 640x480) and the websocket-client module.
Both hold A (fly left) for 1 s, five times, 1.5 s apart, and read the frames from the
viewer's --log (when each frame was shown, or sent to the page, and its pose).
"""
import json
import os
import statistics as st
import subprocess
import sys
import tempfile
import time


def summary(frames, keys):
    mv = [i for i in range(1, len(frames)) if frames[i]["moving"] and frames[i - 1]["moving"]]
    dt = sorted(frames[i]["t"] - frames[i - 1]["t"] for i in mv)
    w = max(x["width"] for x in frames)
    out = {
        "frames": len(frames),
        "moving_frames": len(mv),
        "moving_fps": 1 / st.median(dt),
        "moving_ms_median": st.median(dt) * 1000,
        "moving_ms_p95": dt[int(0.95 * len(dt))] * 1000,
        "moving_width_median": st.median(frames[i]["width"] for i in mv),
        "render_ms_median": st.median(frames[i]["seconds"] for i in mv) * 1000,
        "mrays_s_moving": st.median(frames[i]["rays"] / frames[i]["seconds"] / 1e6 for i in mv),
        "latency_ms": [],
        "sharp_ms": [],
        "resident_mib": frames[-1]["resident_bytes"] >> 20,
        "budget_mib": frames[-1]["budget"] >> 20,
    }
    for kind, t in keys:
        before = [x for x in frames if x["t"] < t]
        after = [x for x in frames if x["t"] >= t]
        if kind == "down":
            moved = [x for x in after if x["eye"] != before[-1]["eye"]]
            out["latency_ms"].append(round((moved[0]["t"] - t) * 1000) if moved else None)
        else:
            sharp = [x for x in after if not x["moving"] and x["width"] == w and x["approx_pixels"] == 0]
            out["sharp_ms"].append(round((sharp[0]["t"] - t) * 1000) if sharp else None)
    return out


def hold_keys(down, up):
    keys = []
    for _ in range(5):
        keys.append(("down", time.time()))
        down()
        time.sleep(1)
        keys.append(("up", time.time()))
        up()
        time.sleep(1.5)
    return keys


def window(cmd, log):
    proc = subprocess.Popen(cmd + ["--log", log], stderr=subprocess.DEVNULL)
    wid = ""
    for _ in range(300):
        r = subprocess.run(["xdotool", "search", "--name", "megaray - "], capture_output=True, text=True)
        if r.stdout.strip():
            wid = r.stdout.split()[0]
            break
        time.sleep(0.2)
    time.sleep(3)
    subprocess.run(["xdotool", "windowfocus", wid])
    keys = hold_keys(lambda: subprocess.run(["xdotool", "keydown", "a"]), lambda: subprocess.run(["xdotool", "keyup", "a"]))
    subprocess.run(["xdotool", "keydown", "Escape"])
    time.sleep(0.3)
    subprocess.run(["xdotool", "keyup", "Escape"])
    proc.wait(30)
    return keys


def serve(cmd, log):
    import websocket  # websocket-client

    srv = subprocess.Popen(cmd + ["--bind", "127.0.0.1:0", "--log", log], stderr=subprocess.PIPE, text=True)
    addr = None
    for line in srv.stderr:
        if "http://" in line:
            addr = line.split("http://")[1].split("/")[0]
            break
    profile = tempfile.mkdtemp()
    chrome = subprocess.Popen(
        ["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0",
         f"--user-data-dir={profile}", "about:blank"], stderr=subprocess.PIPE, text=True)
    for line in chrome.stderr:
        if line.startswith("DevTools listening on "):
            url = line.split(" on ")[1].strip()
            break
    ws = websocket.create_connection(url)
    ids = iter(range(1, 1 << 30))

    def call(method, params, session=None):
        i = next(ids)
        msg = {"id": i, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        ws.send(json.dumps(msg))
        while True:
            r = json.loads(ws.recv())
            if r.get("id") == i:
                return r.get("result")

    t = call("Target.createTarget", {"url": "about:blank"})
    s = call("Target.attachToTarget", {"targetId": t["targetId"], "flatten": True})["sessionId"]
    call("Emulation.setDeviceMetricsOverride", {"width": 640, "height": 480, "deviceScaleFactor": 1, "mobile": False}, s)
    call("Page.navigate", {"url": f"http://{addr}/"}, s)
    time.sleep(4)
    key = lambda kind: call("Input.dispatchKeyEvent", {"type": kind, "code": "KeyA", "key": "a"}, s)
    keys = hold_keys(lambda: key("keyDown"), lambda: key("keyUp"))
    frames = call("Runtime.evaluate", {"expression": "window.megaray.frames", "returnByValue": True}, s)
    print("frames the page drew:", frames["result"]["value"], file=sys.stderr)
    chrome.kill()
    srv.kill()
    return keys


def main():
    if len(sys.argv) < 4 or sys.argv[2] != "--":
        sys.exit(__doc__)
    mode, cmd = sys.argv[1], sys.argv[3:]
    log = tempfile.mktemp(suffix=".jsonl")
    keys = window(cmd, log) if mode == "window" else serve(cmd, log)
    frames = [json.loads(l) for l in open(log)]
    os.unlink(log)
    print(json.dumps({"mode": mode, "command": " ".join(cmd), **summary(frames, keys)}))


if __name__ == "__main__":
    main()
