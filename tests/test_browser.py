"""The explorer (notebook 07) in a real browser: JupyterLab from this environment, driven in
headless Chromium by Playwright.

Chromium is Debian's (`apt-get install chromium`, done by `.ci/run`): Playwright cannot
download its own browser here. Without it the test is skipped, saying so.
"""

from __future__ import annotations

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
    committed notebook stays clean), with the grid's artifacts in the test's folder."""
    root = tmp_path / "lab"
    root.mkdir()
    shutil.copy(NOTEBOOK, root / NOTEBOOK.name)
    env = {k: v for k, v in os.environ.items() if k != OUTPUTS_ENV}
    env.update({ARTIFACTS_ENV: str(tmp_path / "artifacts"), "JUPYTER_RUNTIME_DIR": str(tmp_path)})
    port = _free_port()
    log = tmp_path / "jupyterlab.log"
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "jupyter",
            "lab",
            "--no-browser",
            "--allow-root",
            f"--port={port}",
            "--ip=127.0.0.1",
            f"--ServerApp.root_dir={root}",
            f"--IdentityProvider.token={TOKEN}",
            f"--LabApp.workspaces_dir={tmp_path / 'workspaces'}",
            "--LabApp.news_url=",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=log.open("w"),  # the child holds it; ours closes with the test's process
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
        server.terminate()
        server.wait(timeout=30)


def test_the_explorer_rolls_out_again_when_a_slider_moves(jupyterlab, tmp_path):
    from playwright.sync_api import expect, sync_playwright

    shot = tmp_path / "explorer.png"
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1100})
        try:
            page.set_default_timeout(60_000)
            expect.set_options(timeout=60_000)  # a cold JupyterLab on a busy 2-core machine
            page.goto(f"{jupyterlab}/lab/tree/{NOTEBOOK.name}?token={TOKEN}")
            # The kernel is up once its status says Idle; then Run > Run All Cells.
            expect(page.locator(".jp-Notebook")).to_be_visible()
            expect(page.get_by_role("button", name=re.compile(r"\| Idle"))).to_be_visible()
            news = page.get_by_role("alert").get_by_role("button", name="No")
            if news.is_visible():  # JupyterLab asks once whether to fetch news: it cannot here
                news.click()
            page.locator(".lm-MenuBar-itemLabel", has_text="Run").first.click()
            page.locator(".lm-Menu-itemLabel", has_text="Run All Cells").first.click()

            status, figure = page.locator(".gcdt-status"), page.locator("img.gcdt-figure")
            # The first rollout trains the smoke grid's Reach checkpoint first (seconds).
            expect(status).to_contain_text("rollout 1:", timeout=90_000)
            first_src = figure.get_attribute("src")
            assert first_src, "the first rollout drew no figure"

            # Move the goal's x slider one step (5 mm) with the keyboard, as a user may.
            handle = page.locator(".widget-slider").first.locator(".noUi-handle")
            handle.focus()
            handle.press("ArrowRight")
            expect(status).to_contain_text("rollout 2:", timeout=60_000)
            expect(status).to_contain_text("goal (0.080, -0.075, 0.150)")  # x was 0.075
            expect(figure).not_to_have_attribute("src", first_src)
            page.locator(".gcdt-animation").scroll_into_view_if_needed()
            page.screenshot(path=str(shot), full_page=False)
        except BaseException:
            page.screenshot(path=str(tmp_path / "failure.png"))  # what the browser showed
            raise
        finally:
            browser.close()
    assert shot.stat().st_size > 10_000
    print(f"screenshot: {shot}")
