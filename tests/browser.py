"""Open a local HTML file in headless Chromium (Debian's chromium + chromium-driver) via Selenium."""

from __future__ import annotations

import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def chromium():
    """A headless Chromium WebDriver; fails with the fix when the browser is missing."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    browser, driver_bin = shutil.which("chromium"), shutil.which("chromedriver")
    if not browser or not driver_bin:
        pytest.fail("headless Chromium is missing: run `make browser` (Debian packages chromium chromium-driver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    profile = tempfile.mkdtemp(prefix="garage-mj-chromium-")
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={profile}",
    ):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(executable_path=driver_bin), options=opts)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def page_facts(path: Path) -> dict:
    """Load ``path`` and report its images (loaded or not), tables (with their header and cell texts), links
    and the text a reader sees."""
    with chromium() as driver:
        driver.get(Path(path).resolve().as_uri())
        return driver.execute_script(
            """
            const imgs = Array.from(document.images).map(i => ({src: i.getAttribute('src'),
                loaded: i.complete && i.naturalWidth > 0}));
            const tables = Array.from(document.querySelectorAll('table')).map(t => ({
                id: t.id, rows: t.tBodies.length ? t.tBodies[0].rows.length : 0,
                empty_cells: Array.from(t.querySelectorAll('td')).filter(td => !td.textContent.trim()).length,
                head: Array.from(t.querySelectorAll('th')).map(th => th.textContent),
                cells: t.tBodies.length ? Array.from(t.tBodies[0].rows).map(
                    r => Array.from(r.cells).map(c => c.textContent)) : []}));
            const links = Array.from(document.querySelectorAll('a')).map(a => a.getAttribute('href'));
            return {title: document.title, imgs, tables, links, text: document.body.innerText,
                    headings: Array.from(document.querySelectorAll('h2')).map(h => h.textContent)};
            """
        )


def table_fit(path: Path, width: int, height: int = 900) -> list[dict]:
    """Load ``path`` in a ``width`` x ``height`` window; per table: its id, the window's inner width, the right edge
    of its last header cell, and how far its scroll container (if any) must scroll sideways to show it all."""
    with chromium() as driver:
        driver.set_window_size(width, height)
        driver.get(Path(path).resolve().as_uri())
        return driver.execute_script(
            """
            return Array.from(document.querySelectorAll('table')).map(t => {
                const ths = t.querySelectorAll('th');
                const last = ths[ths.length - 1].getBoundingClientRect();
                const box = t.parentElement;
                return {id: t.id, inner: window.innerWidth, last_right: last.right,
                        page_scroll: document.documentElement.scrollWidth - document.documentElement.clientWidth,
                        box_scroll: box.scrollWidth - box.clientWidth};
            });
            """
        )
