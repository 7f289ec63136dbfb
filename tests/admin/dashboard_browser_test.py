#!/usr/bin/python3
"""The admin dashboard in a real browser: `hysar serve --admin-listen` with two headsets
(hysar-loadgen), the page opened in headless Chromium through chromedriver (python3-selenium).
It must show one row per headset, and each row's thumbnails must change as the headsets move
(their pixels hashed in a canvas). `curl /metrics` must read as Prometheus text. Everything it
started is stopped by PID. Usage: dashboard_browser_test.py BUILD_DIR"""
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service

DEADLINE_S = 120  # for each wait: a failure to get there, not a timing measurement

HASH_JS = """
const out = {};
for (const img of document.querySelectorAll("tr.viewer img.thumb, #projector-img")) {
  if (!img.complete || !img.naturalWidth) continue;
  const c = document.createElement("canvas");
  c.width = img.naturalWidth; c.height = img.naturalHeight;
  const g = c.getContext("2d");
  g.drawImage(img, 0, 0);
  const d = g.getImageData(0, 0, c.width, c.height).data;
  let h = 2166136261, lit = 0;
  for (let i = 0; i < d.length; ++i) h = Math.imul(h ^ d[i], 16777619) >>> 0;
  for (let i = 0; i < d.length; i += 4) lit += d[i] + d[i + 1] + d[i + 2] > 0;
  const row = img.closest("tr");
  const key = row ? row.dataset.viewer + "/" + (img.classList.contains("left") ? "left" : "right")
                  : "projector";
  out[key] = {hash: h, lit: lit, width: c.width, height: c.height};
}
return out;
"""


def fail(message):
    print("dashboard test: FAIL: " + message, file=sys.stderr)
    sys.exit(1)


def wait_for(what, check):
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        value = check()
        if value:
            return value
        time.sleep(0.25)
    fail("gave up waiting for " + what)


def check_prometheus_text(text):
    """A strict reading of the text format: HELP/TYPE lines, samples of declared families."""
    name = r"[a-zA-Z_:][a-zA-Z0-9_:]*"
    label = r'[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\\n]|\\[\\"n])*"'
    sample = re.compile(r"^(%s)(\{%s(?:,%s)*\})? (\S+)$" % (name, label, label))
    types = {}
    if not text.endswith("\n"):
        fail("/metrics does not end with a line feed")
    samples = 0
    for line in text.splitlines():
        m = re.match(r"^# (HELP|TYPE) (%s) (.+)$" % name, line)
        if m:
            if m.group(1) == "TYPE":
                if m.group(3) not in ("counter", "gauge", "summary", "histogram", "untyped"):
                    fail("bad TYPE line: " + line)
                if m.group(2) in types:
                    fail("a second TYPE: " + line)
                types[m.group(2)] = m.group(3)
            continue
        m = sample.match(line)
        if not m:
            fail("not a HELP, TYPE or sample line: %r" % line)
        float(m.group(3))  # raises on a bad value
        family = re.sub(r"_(sum|count)$", "", m.group(1)) if m.group(1) not in types else m.group(1)
        if family not in types:
            fail("a sample without its TYPE: " + line)
        samples += 1
    for want in ("hysar_viewer_frames_total", "hysar_gpu_info", "hysar_stage_seconds"):
        if want not in types:
            fail("/metrics has no " + want)
    return samples


def main():
    build = os.path.abspath(sys.argv[1])
    work = tempfile.mkdtemp(prefix="hysar-dashboard-")
    token = "dashboard-test-token"
    token_file = os.path.join(work, "token")
    with open(os.open(token_file, os.O_WRONLY | os.O_CREAT, 0o600), "w") as f:
        f.write(token + "\n")
    procs = []
    driver = None
    try:
        log = open(os.path.join(work, "serve.log"), "w+")
        server = subprocess.Popen(
            [os.path.join(build, "hysar"), "serve", "--listen", "127.0.0.1:0", "--token-file",
             token_file, "--admin-listen", "0", "--max-viewer-hz", "10"],
            stdout=log, stderr=subprocess.STDOUT)
        procs.append(server)

        def ports():
            log.seek(0)
            text = log.read()
            if server.poll() is not None:
                fail("the server exited:\n" + text)
            serving = re.search(r"serving .* on 127\.0\.0\.1:(\d+)", text)
            admin = re.search(r"admin endpoint on http://127\.0\.0\.1:(\d+)/", text)
            return (serving.group(1), admin.group(1)) if serving and admin else None

        port, admin_port = wait_for("the server's ports", ports)
        base = "http://127.0.0.1:%s" % admin_port

        # Unauthenticated: 401 with a plain message.
        r = subprocess.run(["curl", "-s", "-w", "\n%{http_code}", base + "/metrics"],
                           capture_output=True, text=True, check=True)
        if not r.stdout.endswith("\n401") or "unauthorized" not in r.stdout:
            fail("/metrics without the token answered: %r" % r.stdout)

        loadgen = subprocess.Popen(
            [os.path.join(build, "clients", "hysar-loadgen"), "--connect", "127.0.0.1:" + port,
             "--token-file", token_file, "--viewers", "2", "--rate", "10", "--seconds", "0"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(loadgen)

        options = webdriver.ChromeOptions()
        options.binary_location = "/usr/bin/chromium"
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                    "--window-size=1400,1000"):
            options.add_argument(arg)
        driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
        driver.get(base + "/#token=" + token)
        if token in driver.current_url:
            fail("the token stayed in the address bar: " + driver.current_url)

        def two_rows_with_pictures():
            rows = driver.find_elements("css selector", "tr.viewer")
            hashes = driver.execute_script(HASH_JS)
            thumbs = [k for k in hashes if k != "projector"]
            return hashes if len(rows) == 2 and len(thumbs) == 4 and "projector" in hashes else None

        first = wait_for("two viewer rows with both thumbnails and the projector frame",
                         two_rows_with_pictures)
        if len(driver.find_elements("css selector", "tr.viewer")) != 2:
            fail("not two viewer rows")
        for key, h in first.items():
            if h["width"] <= 0 or h["height"] <= 0:
                fail("an empty picture: " + key)
        if first["projector"]["lit"] == 0:
            fail("the projector frame is black")
        names = [e.text for e in driver.find_elements("css selector", "tr.viewer td.name")]
        if len(names) != 2 or not all(names):
            fail("the rows do not show the headsets' names: %r" % names)
        for field in ("rate", "p50", "bps", "mbps", "quality", "cap"):
            cells = driver.find_elements("css selector", 'tr.viewer td[data-field="%s"]' % field)
            if len(cells) != 2 or not all(c.text for c in cells):
                fail("the rows do not show " + field)

        def all_changed():
            now = driver.execute_script(HASH_JS)
            return all(k in now and now[k]["hash"] != first[k]["hash"]
                       for k in first if k != "projector")

        wait_for("every thumbnail to change as the headsets move", all_changed)
        later = driver.execute_script(HASH_JS)
        if not any(v["lit"] > 0 for k, v in later.items() if k != "projector"):
            fail("every headset thumbnail is black")

        r = subprocess.run(["curl", "-sf", "-H", "Authorization: Bearer " + token,
                            base + "/metrics"], capture_output=True, text=True, check=True)
        samples = check_prometheus_text(r.stdout)
        for series in ("hysar_sessions{role=\"headset\"} 2",):
            if series not in r.stdout:
                fail("/metrics lacks " + series)
        print("dashboard test: two rows, thumbnails changed, /metrics parsed (%d samples)" % samples)
    finally:
        if driver is not None:
            driver.quit()
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


if __name__ == "__main__":
    main()
