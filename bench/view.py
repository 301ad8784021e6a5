"""Benchmark: the live view keeps up with the device; the frame rate the browser draws.

The device runs in its own process (`eyehil emulate --link tcp --script demo --render-workers N`, guestrin2006:
one eye, one 320 x 240 crop per exposure, rendered ahead in `VIEW_RENDER_WORKERS` processes, default 1); the
view (`eyehil.drivers.view.server.ViewServer`) runs in this process and a real headless Chromium (Debian's,
driven by Playwright) shows the page. Two streams, features and images both: 250 Hz (the device renders what
it can, the rest counted in its
`frames_dropped` by design) and 60 Hz (an image for every exposure). Over `SECONDS` of wall time: samples per
second received, images per second the page received and drew (its own count, window.eyehilView; beside it the
page's animation frames per second, the most images it can draw), and the loss
counters that must stay at zero: the device's `samples_dropped`, the host's lost frames, overflowed samples and
incomplete images, and the messages the view dropped for a slow page. Target (issue 14): with 250 Hz features
and 60 Hz frames, loss counters zero; the page draws every image at 60 Hz (>= `TARGET_FPS`). The page keeps up
when it draws at least `KEEP_UP` of the images the view receives, or of its animation frames where more images
arrive than it has frames (`drawable`), with the loss counters at zero; beside it, what
a bare host (no view, no page) receives from the same device just before: on a loaded machine the device renders
fewer images than its rate, and fewer still when the view and the browser take their share of the CPU.
"""

from __future__ import annotations

import os
import time

from bench.device import emulator
from eyehil.drivers.client import open_tracker
from eyehil.drivers.view.server import ViewServer
from eyehil.protocols.enums import StreamSelect

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]
RATES = (250, 60)
SECONDS = 5.0
TARGET_FPS = 55.0
KEEP_UP = 0.9  # the page draws at least this share of the images the view receives
#: the device renders its images in this many processes ahead of the link (`--render-workers`; 0: on its thread)
RENDER_WORKERS = int(os.environ.get("VIEW_RENDER_WORKERS", "1"))
LOSS = ("samples_dropped", "lost_frames", "samples_overflowed", "images_incomplete", "view_dropped")


def bare_host(url: str, seconds: float) -> float:
    """Images per second a bare host (no view, no page) receives from the same device: what there is to show."""
    with open_tracker(url) as tracker:
        tracker.configure(stream=StreamSelect.BOTH)
        tracker.start()
        while not tracker.wire.images:
            tracker.wire.pump(1.0)
        first, start = tracker.stats.images, time.perf_counter()
        while time.perf_counter() - start < seconds:
            tracker.wire.pump(0.05)
            tracker.wire.images.clear()
            tracker.wire.samples.clear()
        received = (tracker.stats.images - first) / (time.perf_counter() - start)
        tracker.stop()
    return received


def _counters(view: ViewServer) -> dict:
    session = view.session
    return {**session.tracker.stats.as_dict(), **session.device_status, **session.counters,
            "view_dropped": view.hub.dropped}


def once(browser, rate_hz: int, seconds: float = SECONDS) -> dict:
    """One run at `rate_hz`; rates per wall second and the loss counters' increase."""
    with emulator("--link", "tcp", "--rate", str(rate_hz), "--render-workers", str(RENDER_WORKERS)) as url:
        bare = bare_host(url, seconds)
        result = _with_page(browser, url, seconds)
    return {"rate_hz": rate_hz, "bare_images_per_s": bare, **result}


def _with_page(browser, url: str, seconds: float) -> dict:
    """The view and a page on `url` for `seconds`."""
    with ViewServer(url, max_image_hz=1000) as view:
        page = browser.new_page()
        page.goto(view.address)
        page.wait_for_function("window.eyehilView.imagesDrawn > 10 && window.eyehilView.stats.samples_sent > 0",
                               timeout=60_000)
        count = ("[window.eyehilView.imagesDrawn, window.eyehilView.animationFrames, window.eyehilView.imagesReceived,"
                 " window.eyehilView.imagesSkipped]")
        before, (drawn0, frames0, got0, skip0), start = _counters(view), page.evaluate(count), time.perf_counter()
        time.sleep(seconds)
        (drawn1, frames1, got1, skip1), after = page.evaluate(count), _counters(view)
        elapsed = time.perf_counter() - start
        time.sleep(1.2)  # one more STATUS poll: the device's drops up to the end of the window
        final = _counters(view)
        page.close()
    delta = {k: after[k] - before.get(k, 0) for k in after}
    return {"samples_per_s": delta["samples"] / elapsed, "images_per_s": delta["images"] / elapsed,
            "page_fps": (drawn1 - drawn0) / elapsed, "animation_fps": (frames1 - frames0) / elapsed,
            "page_received_per_s": (got1 - got0) / elapsed, "page_skipped": skip1 - skip0,
            "frames_dropped": final["frames_dropped"] - before["frames_dropped"],
            "loss": {k: final[k] - before.get(k, 0) for k in LOSS}}


def run(repeats: int = 3) -> dict:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            return {rate: max((once(browser, rate) for _ in range(repeats)), key=lambda r: r["page_fps"])
                    for rate in RATES}
        finally:
            browser.close()


def drawable(r: dict) -> float:
    """Images per second the page could draw: those it received, but at most one an animation frame (a page shows the
    newest image of each frame; at 250 Hz the device renders some 200 images a second, more than headless Chromium's
    110-120 frames)."""
    return min(r["images_per_s"], r["animation_fps"])


def report(results: dict) -> str:
    parts = []
    for rate, r in results.items():
        lossless = not any(r["loss"].values())
        parts.append(f"{rate} Hz: {r['samples_per_s']:.0f} samples/s, {r['images_per_s']:.1f} images/s received "
                     f"(a bare host: {r['bare_images_per_s']:.1f}), "
                     f"page received {r['page_received_per_s']:.1f}/s, drew {r['page_fps']:.1f}/s "
                     f"({r['page_skipped']} skipped) in {r['animation_fps']:.1f} animation frames/s "
                     f"(device skipped {r['frames_dropped']} images by design); "
                     f"loss counters {'all zero' if lossless else r['loss']}")
    lossless = all(not any(r["loss"].values()) for r in results.values())
    r60 = results.get(60)
    verdict = "PASS" if r60 and r60["page_fps"] >= TARGET_FPS and lossless else "FAIL"
    keeps_up = "PASS" if lossless and all(r["page_fps"] >= KEEP_UP * drawable(r) for r in results.values()) else "FAIL"
    return ("live view in headless Chromium, device in its own process on TCP, features + 320x240 images: "
            + "; ".join(parts) + f"; the page draws >= {KEEP_UP:.0%} of the images received (of its animation frames "
            "where more images arrive than it has frames), zero loss: "
            f"{keeps_up}; target 60 Hz images drawn (>= {TARGET_FPS:.0f}/s) with zero loss: {verdict}")


if __name__ == "__main__":
    print(report(run(1)))
