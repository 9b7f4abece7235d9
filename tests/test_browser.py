"""The explorer (notebook 07) in a real browser: JupyterLab from this environment, driven in
headless Chromium by Playwright.

Chromium is Debian's (`apt-get install chromium`, done by `.ci/run`): Playwright cannot
download its own browser here. Without it the test is skipped, saying so.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from gcdt.paths import ARTIFACTS_ENV, OUTPUTS_ENV

NOTEBOOK = Path(__file__).resolve().parent.parent / "notebooks" / "07_explorer.ipynb"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Headless, as root in a container, on a machine with no route out: no sandbox, and none of
# Chromium's background connections (each would be refused and retried).
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
TOKEN = "gcdt-browser-test"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        CHROMIUM is None,
        reason="no Chromium: install Debian's chromium package (bash .ci/run does) to run "
        "the explorer in a real browser",
    ),
]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def jupyterlab(tmp_path):
    """A JupyterLab server over a copy of notebook 07 (JupyterLab saves what it opens: the
    committed notebook stays clean), its outputs and the grid's artifacts in the test's folder."""
    from jupyter_client.kernelspec import KernelSpecManager

    kernel = json.loads(NOTEBOOK.read_text())["metadata"]["kernelspec"]["name"]
    if kernel not in KernelSpecManager().find_kernel_specs():
        pytest.fail(f"no Jupyter kernel {kernel!r}: `make install` registers it")
    root = tmp_path / "lab"
    root.mkdir()
    shutil.copy(NOTEBOOK, root / NOTEBOOK.name)
    env = {
        **os.environ,
        OUTPUTS_ENV: str(tmp_path / "outputs"),
        ARTIFACTS_ENV: str(tmp_path / "artifacts"),
        "JUPYTER_RUNTIME_DIR": str(tmp_path / "runtime"),
    }
    port = _free_port()
    log = tmp_path / "jupyterlab.log"
    with log.open("w") as stderr:
        server = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "jupyter",
                "lab",
                "--no-browser",
                "--allow-root",
                f"--port={port}",
                "--ServerApp.port_retries=0",  # the port we poll, or fail
                "--ip=127.0.0.1",
                f"--ServerApp.root_dir={root}",
                f"--IdentityProvider.token={TOKEN}",
                f"--LabApp.workspaces_dir={tmp_path / 'workspaces'}",
                "--LabApp.news_url=",
                "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                urllib.request.urlopen(f"{url}/api/status?token={TOKEN}", timeout=2)
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    pytest.fail(f"JupyterLab did not start:\n{log.read_text()[-2000:]}")
                time.sleep(0.5)
        yield url
    finally:
        server.terminate()  # JupyterLab shuts its kernel down with it
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()


def test_the_explorer_rolls_out_again_when_a_slider_moves(jupyterlab, tmp_path):
    from playwright.sync_api import expect, sync_playwright

    shot, wait = tmp_path / "explorer.png", 60_000  # ms: a cold JupyterLab on 2 busy cores
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1100})
        page.set_default_timeout(wait)
        idle = page.get_by_role("button", name=re.compile(r"\| Idle"))  # the kernel's status
        try:
            page.goto(f"{jupyterlab}/lab/tree/{NOTEBOOK.name}?token={TOKEN}")
            expect(page.locator(".jp-Notebook")).to_be_visible(timeout=wait)
            expect(idle).to_be_visible(timeout=wait)
            page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
            page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()

            status, figure = page.locator(".gcdt-status"), page.locator("img.gcdt-figure")
            # The first rollout trains the smoke grid's Reach checkpoint first (seconds).
            expect(status).to_contain_text("rollout 1:", timeout=90_000)
            first_src = figure.get_attribute("src")
            assert first_src, "the first rollout drew no figure"
            # The last cell prints the first rollout's summary: every cell has run.
            done = page.locator(".jp-RenderedText pre", has_text=", return ")
            expect(done.first).to_be_visible(timeout=wait)

            # Move the goal's x slider one step (5 mm) with the keyboard, as a user may.
            handle = page.locator(".widget-slider").first.locator(".noUi-handle")
            handle.focus()
            handle.press("ArrowRight")
            expect(status).to_contain_text("rollout 2:", timeout=wait)
            expect(status).to_contain_text("goal (0.080, -0.075, 0.150)")  # x was 0.075
            # The browser received a new figure (ipywidgets sends one per new value).
            expect(figure).not_to_have_attribute("src", first_src)
            expect(idle).to_be_visible(timeout=wait)
            expect(status).to_contain_text("rollout 2:")  # one move, one rollout
            page.locator(".gcdt-animation").scroll_into_view_if_needed()
            page.screenshot(path=str(shot))
        except BaseException:
            with contextlib.suppress(Exception):  # what the browser showed; the error stays
                page.screenshot(path=str(tmp_path / "failure.png"))
            raise
        finally:
            browser.close()
    assert shot.stat().st_size > 10_000
    print(f"screenshot: {shot}")
