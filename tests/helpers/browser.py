"""Report pages in a real headless browser: Debian's chromium driven by selenium through
/usr/bin/chromedriver (`make setup` installs both). WebGL runs on chromium's software renderer
(SwiftShader), so the 3D view draws without a GPU."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
WINDOW = (1280, 1600)
"""The browser window, CSS pixels (device pixel ratio 1)."""


def start_browser():
    """A headless chromium WebDriver (quit it when done)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    for path in (CHROMIUM, CHROMEDRIVER):
        assert Path(path).is_file(), f"{path} missing: run `make setup` (installs chromium and chromium-driver)"
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={WINDOW[0]},{WINDOW[1]}", "--allow-file-access-from-files"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


def screenshot(driver) -> np.ndarray:
    """(H, W, 3) uint8 RGB of the browser's viewport."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(driver.get_screenshot_as_png())).convert("RGB"))


def check_page(driver, path: Path) -> dict:
    """Load ``path`` from disk; assert no SEVERE console entry, no broken image, a screenshot
    that is not blank, and nothing fetched from elsewhere. Returns facts about the page."""
    text = path.read_text()
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:|#)""", text), "a resource outside the file"
    driver.get(path.resolve().as_uri())
    images = driver.execute_script(
        "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth, i.src.slice(0, 11)])")
    severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe
    assert images, "no images"
    broken = [alt for alt, complete, width, _ in images if not complete or width <= 0]
    assert not broken, f"broken images: {broken}"
    assert all(src.startswith("data:image") for *_, src in images)
    shot = screenshot(driver).mean(axis=2)
    assert shot.std() > 10.0, f"blank screenshot (std {shot.std():.1f})"
    return {"images": [alt for alt, *_ in images], "text": driver.find_element("tag name", "body").text}


def view_call(driver, view_id: str, call: str):
    """Scroll the 3D view ``view_id`` (report/view3d.py) to the top of the window and return
    ``window.mpView3d[view_id].<call>`` (e.g. ``"projectedTags()"``)."""
    driver.execute_script(f"document.getElementById('{view_id}').scrollIntoView({{block: 'start'}})")
    return driver.execute_script(f"return window.mpView3d['{view_id}'].{call}")


def click_tag(driver, view_id: str, kind: str, index: int) -> list[str]:
    """Click tag ``index`` of ``kind`` (``planned`` or ``found``) of the 3D view where the current
    camera shows it (asserts the view sees it there); returns the ids of the selected elements."""
    from selenium.webdriver.common.action_chains import ActionChains

    t = [p for p in view_call(driver, view_id, "projectedTags()") if p["kind"] == kind and p["index"] == index][0]
    assert t["visible"], t
    canvas = driver.find_element("css selector", f"#{view_id} canvas")
    r = driver.execute_script("var r = arguments[0].getBoundingClientRect(); return [r.left, r.top, r.width, r.height]",
                              canvas)
    ActionChains(driver).move_to_element_with_offset(canvas, int(round(t["x"] - r[0] - r[2] / 2)),
                                                     int(round(t["y"] - r[1] - r[3] / 2))).click().perform()
    return driver.execute_script("return Array.from(document.querySelectorAll('.mp-selected')).map(e => e.id)")
