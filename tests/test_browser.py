"""The picker and the review in a real browser: JupyterLab + ipympl driven by headless Chromium.

The test starts its own JupyterLab on localhost (own config, runtime, settings and
workspace dirs; ``--allow-root``), writes small notebooks into a temporary folder (never the
committed ones: JupyterLab autosaves outputs into what it opens), and drives Debian's
``chromium`` through ``chromium-driver`` and selenium: it clicks in the ipympl figure as a
person does and checks each action by what the widget shows and what it writes to disk.
Screenshots of every step go to ``tests/artifacts/browser/`` (git-ignored).

Skipped, with the reason, when Chromium, its driver, selenium or JupyterLab is missing
(``.ci/run`` installs them; ``apt-get install chromium chromium-driver``).
"""
from __future__ import annotations

import json
import importlib.util
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "data-samples" / "flapping"
ARTIFACTS = REPO / "tests" / "artifacts" / "browser"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
FIGSIZE = 6.0  # inches; the picker's figure is square, the sample images are 512 x 512

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::ResourceWarning")


def _require():
    if CHROMIUM is None or CHROMEDRIVER is None:
        pytest.skip("no Chromium: install Debian's chromium and chromium-driver (apt-get install chromium "
                    "chromium-driver; .ci/run does) to run the real-browser widget tests")
    for module in ("selenium", "jupyterlab", "ipympl"):
        # find_spec, not import: importing ipympl switches this process's matplotlib backend
        # to ipympl, and every later test's figure would then need a Jupyter kernel
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed: pip install -e '.[test]' to run the real-browser widget tests")
    if not (SAMPLES / "picks.json").is_file():
        pytest.skip("data-samples/flapping is absent")


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _notebook(cells):
    return {
        "cells": [{"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [],
                   "source": src} for src in cells],
        "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}},
        "nbformat": 4, "nbformat_minor": 5,
    }


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A JupyterLab server of its own on localhost: (base url, token, notebook folder)."""
    _require()
    root = tmp_path_factory.mktemp("lab")
    work = root / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND", "WINGPHOTO_HEADLESS")}
    for name in ("JUPYTER_CONFIG_DIR", "JUPYTER_RUNTIME_DIR", "JUPYTERLAB_SETTINGS_DIR",
                 "JUPYTERLAB_WORKSPACES_DIR", "IPYTHONDIR", "MPLCONFIGDIR"):
        (root / name.lower()).mkdir()
        env[name] = str(root / name.lower())
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    # no "notified about Jupyter news?" toast over the figure
    settings = root / "jupyterlab_settings_dir" / "@jupyterlab" / "apputils-extension"
    settings.mkdir(parents=True)
    (settings / "notification.jupyterlab-settings").write_text(json.dumps({"fetchNews": "false",
                                                                            "checkForUpdates": False}))
    token = "wingphoto-test-token"
    log = open(root / "lab.log", "w")
    deadline = time.monotonic() + 180  # a busy CI machine can take a minute to start it
    for attempt in range(3):
        # the free port is found by binding and releasing it: another process can take it
        # before JupyterLab binds it (port_retries=0 then makes Lab exit); try a new port then
        port = _free_port()
        proc = subprocess.Popen(
            [sys.executable, "-m", "jupyter", "lab", "--no-browser", "--allow-root", f"--port={port}",
             "--ServerApp.ip=127.0.0.1", f"--ServerApp.root_dir={work}", f"--IdentityProvider.token={token}",
             "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
             "--ServerApp.port_retries=0"],
            cwd=work, env=env, stdout=log, stderr=subprocess.STDOUT)
        base = f"http://127.0.0.1:{port}"
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                urllib.request.urlopen(f"{base}/api/status?token={token}", timeout=2).read()
                break
            except OSError:
                time.sleep(0.5)
        else:
            if proc.poll() is None:  # still starting at the deadline
                proc.kill()
            proc.wait()
            if attempt < 2 and time.monotonic() < deadline:
                continue
            log.close()
            pytest.fail("JupyterLab did not start:\n" + (root / "lab.log").read_text()[-3000:])
        break
    yield base, token, work
    proc.terminate()
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
    log.close()


@pytest.fixture(scope="module")
def browser(lab, tmp_path_factory):
    """Headless Chromium under chromium-driver (no browser download at run time)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tmp_path_factory.mktemp("chromium-profile")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--disable-dev-shm-usage", f"--user-data-dir={profile}", "--window-size=1500,1100",
                 "--force-device-scale-factor=1"):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


class Lab:
    """A person at JupyterLab: open a notebook, run it, click in figures, press buttons."""

    def __init__(self, driver, base, token, name):
        self.d, self.base, self.token, self.name = driver, base, token, name
        self.step = 0
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        for old in ARTIFACTS.glob(f"{name}_*.png"):  # this run's screenshots only
            old.unlink()

    def shot(self, what):
        self.step += 1
        self.d.save_screenshot(str(ARTIFACTS / f"{self.name}_{self.step:02d}_{what}.png"))

    def wait(self, condition, what, timeout=120.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                self._accept_kernel_dialog()
                value = condition()
            except Exception:  # noqa: BLE001 - DOM in flux; retry until the deadline
                value = None
            if value:
                return value
            time.sleep(0.25)
        self.shot("timeout")
        raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")

    def xpath(self, path):
        from selenium.webdriver.common.by import By

        return self.d.find_elements(By.XPATH, path)

    def css(self, selector):
        from selenium.webdriver.common.by import By

        return self.d.find_elements(By.CSS_SELECTOR, selector)

    def open(self, notebook, marker):
        self.marker = marker
        self.d.get(f"{self.base}/lab/tree/{notebook}?token={self.token}")
        self.wait(lambda: self.panel() is not None, "the notebook to open")
        self.wait(self._own_kernel_idle, "the kernel to start")

    def panel(self):
        """The notebook panel of this person's notebook (the one whose code holds ``marker``).

        JupyterLab restores the tabs of earlier tests: the picker's executed notebook stays
        open, hidden, when the review opens, with its own idle kernel indicator and "[1]:"
        prompts. Read from the whole page, those said "kernel idle, cells ran" while the
        review's kernel was still starting: a run on 2026-12-02 lost the review's first two
        cells and waited 120 s for a widget that could not come.
        """
        for panel in self.css(".jp-NotebookPanel"):
            if panel.find_elements("css selector", ".jp-Cell") and \
                    self.marker in (panel.get_attribute("textContent") or ""):
                return panel
        return None

    def _own_kernel_idle(self):
        panel = self.panel()
        if panel is None:
            return False
        status = [e.get_attribute("data-status")
                  for e in panel.find_elements("css selector", ".jp-Notebook-ExecutionIndicator")]
        if any(status):
            return "idle" in status
        return self._kernel_idle()  # the status bar shows the current notebook's kernel

    def _accept_kernel_dialog(self):
        """Accept JupyterLab's "Select Kernel" dialog (the notebook's own python3 preselected).

        On a busy machine Lab sometimes asks for the kernel although the notebook names it,
        and the dialog then covers the figure. Every :meth:`wait` calls this first.
        """
        for dialog in self.css(".jp-Dialog"):
            if "Select Kernel" in (dialog.text or ""):
                for button in dialog.find_elements("css selector", ".jp-Dialog-button.jp-mod-accept"):
                    button.click()

    def _kernel_idle(self):
        return any("Idle" in (e.text or "") or "Idle" in (e.get_attribute("title") or "")
                   for e in self.css(".jp-StatusBar-TextItem, .jp-Toolbar-kernelStatus, .jp-KernelStatus"))

    def menu(self, top, item):
        """Click ``item`` of menu ``top``, opening the menu again if it closed or never opened.

        On a busy machine the first click can come before the menu bar takes clicks, or a
        notebook finishing its load takes the focus and closes the open menu.
        """
        top_path = f"//div[contains(@class,'lm-MenuBar-itemLabel') and text()='{top}']"
        item_path = f"//div[contains(@class,'lm-Menu-itemLabel') and text()='{item}']"

        def clicked():
            shown = [e for e in self.xpath(item_path) if e.is_displayed()]
            if shown:
                shown[0].click()
                return True
            if not any(m.is_displayed() for m in self.css(".lm-Menu")):
                self.xpath(top_path)[0].click()
            return False

        self.wait(clicked, f"menu item {top} > {item}")

    def run_all(self):
        """Run every cell, and check that the kernel took the request for every cell.

        Taken: every prompt of this notebook shows [*] or a count, and the prompts changed
        (a reopened notebook shows the counts it was saved with, "[1]:"). On a busy machine
        Lab can swallow a request, or part of it (a late "Select Kernel" dialog, a kernel
        still connecting: cells left at "[ ]:"); then the request is made again, up to
        three times.
        """
        before = self.prompts()
        for attempt in range(3):
            self.menu("Run", "Run All Cells")
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                self._accept_kernel_dialog()
                prompts = self.prompts()
                if prompts and prompts != before and all(any(ch.isdigit() or ch == "*" for ch in p)
                                                         for p in prompts):
                    return
                time.sleep(0.5)
        self.shot("run_all")
        raise AssertionError("JupyterLab did not run the cells after three 'Run All Cells' requests")

    def prompts(self):
        """Input prompts ("[ ]:", "[*]:", "[3]:") of this person's notebook (see :meth:`panel`)."""
        panel = self.panel()
        if panel is None:
            return []
        return [e.get_attribute("textContent") or "" for e in panel.find_elements("css selector", ".jp-InputPrompt")]

    def status_text(self, marker):
        """Text of the widget HTML that contains ``marker`` (the status line)."""
        for e in self.css(".widget-html-content"):
            if marker in e.text:
                return e.text
        return ""

    def wait_status(self, marker, expected, what, timeout=120.0):
        return self.wait(lambda: (lambda t: t if all(x in t for x in expected) else "")(self.status_text(marker)),
                         f"{what} (status containing {expected})", timeout)

    def canvas(self, index=0):
        """The ipympl canvas that receives the mouse (the top one) of the ``index``-th figure.

        Waits until that canvas is laid out (a size and a place on the page): right after a
        redraw, or on a busy machine, ipympl's top canvas can exist with no size yet, and a
        click on it fails with "has no size and location" (a CI run on 2026-12-01).
        """
        def laid_out():
            fig = self.css(".jupyter-matplotlib-canvas-div")[index]
            self.d.execute_script("arguments[0].scrollIntoView({block: 'center'});", fig)
            top = fig.find_elements("css selector", "canvas")[-1]
            rect = top.rect
            return top if top.is_displayed() and rect["width"] > 0 and rect["height"] > 0 else None

        canvas = self.wait(laid_out, f"a laid-out ipympl figure {index}")
        time.sleep(0.5)
        return canvas

    def _offset(self, canvas, x, y, size, axes_box=(0.0, 0.0, 1.0, 1.0)):
        """Offset from the canvas centre of image pixel (x, y) drawn in an axes box (figure fraction)."""
        w, h = canvas.size["width"], canvas.size["height"]
        left, bottom, aw, ah = axes_box
        u = (left + aw * (x + 0.5) / size[0]) * w
        v = (1.0 - bottom - ah + ah * (y + 0.5) / size[1]) * h
        return u - w / 2.0, v - h / 2.0

    def click(self, canvas, x, y, size, axes_box=(0.0, 0.0, 1.0, 1.0), index=0):
        """Click image pixel (x, y); if the canvas was replaced or not laid out, find it again (3 tries)."""
        from selenium.common.exceptions import ElementNotInteractableException, StaleElementReferenceException
        from selenium.webdriver.common.action_chains import ActionChains

        for attempt in range(3):
            try:
                du, dv = self._offset(canvas, x, y, size, axes_box)
                ActionChains(self.d).move_to_element_with_offset(canvas, round(du), round(dv)).click().perform()
                return
            except (ElementNotInteractableException, StaleElementReferenceException):
                if attempt == 2:
                    self.shot("click_failed")
                    raise
                time.sleep(1.0)
                canvas = self.canvas(index)

    def drag(self, canvas, x0, y0, x1, y1, size, axes_box=(0.0, 0.0, 1.0, 1.0)):
        from selenium.webdriver.common.action_chains import ActionChains

        du0, dv0 = self._offset(canvas, x0, y0, size, axes_box)
        du1, dv1 = self._offset(canvas, x1, y1, size, axes_box)
        a = ActionChains(self.d).move_to_element_with_offset(canvas, round(du0), round(dv0)).click_and_hold()
        steps = 6
        for k in range(1, steps + 1):
            a = a.move_to_element_with_offset(canvas, round(du0 + (du1 - du0) * k / steps),
                                              round(dv0 + (dv1 - dv0) * k / steps)).pause(0.05)
        a.release().perform()

    def button(self, text, index=0):
        buttons = self.wait(lambda: [b for b in self.css("button.jupyter-button") if b.text.strip() == text],
                            f"button {text}")
        self.d.execute_script("arguments[0].scrollIntoView({block: 'center'});", buttons[index])
        buttons[index].click()


def _truth(n_points=3):
    t = pd.read_csv(SAMPLES / "truth_tracks.csv")
    t = t[(t["frame"] == 0) & (t["point"] < n_points)]
    return {cam: t[t["camera"] == cam].sort_values("point")[["x", "y"]].to_numpy() for cam in ("left", "right")}


# ------------------------------------------------------------------------------------ picker
def test_picker_in_jupyterlab(lab, browser):
    base, token, work = lab
    picks = work / "picks.json"
    (work / "pick.ipynb").write_text(json.dumps(_notebook([
        "%matplotlib widget",
        "import wingphoto as wp\nfrom wingphoto.widgets import Picker\n"
        f"left = wp.read_sequence({str(SAMPLES / 'left')!r})\nright = wp.read_sequence({str(SAMPLES / 'right')!r})",
        f"picker = Picker.load_or_pick(left, right, picks_path={str(picks)!r}, n_points=3, half_size=(6, 6), "
        f"figsize=({FIGSIZE}, {FIGSIZE}))\npicker",
    ])))
    size = (512, 512)
    truth = _truth()
    me = Lab(browser, base, token, "picker")
    me.open("pick.ipynb", "Picker.load_or_pick(")
    me.run_all()
    me.wait_status("active point", ["left view", "active point 0"], "the picker")
    me.shot("opened")
    canvas = me.canvas()
    for cam in ("left", "right"):
        if cam == "right":
            me.button("right")
            me.wait_status("active point", ["right view", "active point 0"], "the right view")
            canvas = me.canvas()
        for k, (x, y) in enumerate(truth[cam]):
            me.click(canvas, x, y, size)
            me.wait_status("active point", [f"{cam}: {k + 1} placed"], f"{cam} marker {k}")
            me.shot(f"{cam}_clicked_{k}")
    me.wait_status("active point", ["complete"], "complete picks")
    # one screen pixel is 512 / 600 image px: every click lands within about one screen pixel
    screen_px = size[0] / (FIGSIZE * 100)
    me.button("Save")
    me.wait(lambda: picks.is_file(), "the picks file")
    me.wait_status("active point", ["saved 3 markers"], "the save confirmation")
    first = json.loads(picks.read_text())
    for cam in ("left", "right"):
        got = np.array([[p["x"], p["y"]] for p in first["picks"][cam]])
        assert np.abs(got - truth[cam]).max() <= 1.5 * screen_px, (cam, got, truth[cam])
    # drag marker 1's box (right view) by 12 px: its centre moves by the drag
    x1, y1 = truth["right"][1]
    canvas = me.canvas()
    me.drag(canvas, x1 + 2, y1 + 2, x1 + 14, y1 + 2, size)
    me.shot("dragged")
    me.button("Save")
    me.wait(lambda: json.loads(picks.read_text())["picks"]["right"][1]["x"] > first["picks"]["right"][1]["x"] + 8,
            "the dragged marker in the saved file")
    dragged = json.loads(picks.read_text())["picks"]["right"][1]
    assert abs(dragged["x"] - first["picks"]["right"][1]["x"] - 12) <= 1.5 * screen_px
    assert abs(dragged["y"] - first["picks"]["right"][1]["y"]) <= 1.5 * screen_px
    me.button("Undo")
    me.button("Save")
    me.wait(lambda: json.loads(picks.read_text())["picks"] == first["picks"], "the undone drag in the saved file")
    me.shot("undone")
    # reload the page and re-run: load_or_pick opens the saved picks; saving again changes nothing
    before = picks.read_bytes()
    browser.refresh()
    me.open("pick.ipynb", "Picker.load_or_pick(")
    me.run_all()
    me.wait_status("active point", ["left: 3 placed", "right: 3 placed", "complete"], "the reloaded picks")
    me.shot("reloaded")
    me.button("Save")
    me.wait_status("active point", ["saved 3 markers"], "the second save")
    assert json.loads(picks.read_text())["picks"] == json.loads(before)["picks"]


# ------------------------------------------------------------------------------------ review
def test_review_in_jupyterlab(lab, browser):
    base, token, work = lab
    log = work / "corrections.csv"
    tracks = work / "tracks.csv"
    truth = pd.read_csv(SAMPLES / "truth_tracks.csv")
    t = truth[(truth["frame"] < 12) & (truth["point"] < 6)].copy()
    bad = (t["camera"] == "left") & (t["point"] == 2) & (t["frame"] == 5)
    t.loc[bad, "x"] += 7.0  # a wrong position, flagged
    t.loc[bad, "status"] = "flagged"
    t.loc[bad, "score"] = 0.4
    t.to_csv(tracks, index=False)
    true_xy = truth[(truth["camera"] == "left") & (truth["point"] == 2) & (truth["frame"] == 5)][["x", "y"]]
    tx, ty = true_xy.to_numpy()[0]
    (work / "review.ipynb").write_text(json.dumps(_notebook([
        "%matplotlib widget",
        "import wingphoto as wp\nfrom wingphoto.widgets import TrackReview\n"
        f"frames = {{'left': wp.read_sequence({str(SAMPLES / 'left')!r}), "
        f"'right': wp.read_sequence({str(SAMPLES / 'right')!r})}}\n"
        f"tracks = wp.read_tracks_csv({str(tracks)!r})",
        f"review = TrackReview(frames, tracks, corrections_path={str(log)!r}, figsize=({FIGSIZE}, {FIGSIZE}))\n"
        "review.widget",
    ])))
    me = Lab(browser, base, token, "review")
    me.open("review.ipynb", "TrackReview(")
    me.run_all()
    me.wait_status("flagged/lost", ["1 flagged/lost items"], "the review")
    me.shot("opened")
    option = me.wait(lambda: [o for o in me.css("select option")  # ipywidgets writes spaces as nbsp
                              if o.text.replace("\xa0", " ").startswith("frame 5, point 2, left")],
                     "the flagged point in the problem list")[0]
    option.click()
    me.wait_status("flagged/lost", ["frame 5/", "point 2 (flagged)"], "the flagged point selected")
    me.shot("selected")
    me.click(me.canvas(), tx, ty, (512, 512))
    status = me.wait_status("flagged/lost", ["point 2 corrected at frame 5", "1 corrections"], "the correction",
                            timeout=180)
    me.shot("corrected")
    assert "re-tracked forward" in status, status
    assert "0 flagged/lost items" in status
    me.button("Save")
    me.wait(lambda: log.is_file(), "the corrections log")
    c = pd.read_csv(log)
    assert c[["camera", "point", "frame"]].values.tolist() == [["left", 2, 5]]
    screen_px = 512 / (FIGSIZE * 100)
    assert abs(c["x"].iloc[0] - tx) <= 1.5 * screen_px and abs(c["y"].iloc[0] - ty) <= 1.5 * screen_px
    me.shot("saved")
