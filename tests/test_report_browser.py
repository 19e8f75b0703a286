"""The report page in a real browser: headless Chromium (Debian's ``chromium``) driven by
Playwright (``pip install '.[browser]'``). It loads the page of the stored results, finds
no console error, follows two in-page links and checks the summary's counts against each
experiment's claims.csv. Skipped, saying so, where either is missing; CI installs both."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = os.environ.get("ESTIM_CHROMIUM") or shutil.which("chromium") or shutil.which(
    "chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
"""Chromium's flags for a closed network (no background connections) and a root user."""

sync_api = pytest.importorskip("playwright.sync_api",
                               reason="Playwright is not installed (pip install '.[browser]')")
pytestmark = [pytest.mark.skipif(CHROMIUM is None,
                                 reason="no Chromium on this machine (apt-get install chromium)"),
              pytest.mark.slow]                     # a browser: .ci/run's second pytest call


@pytest.fixture(scope="module")
def page_file(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report") / "report.html"
    done = subprocess.run([sys.executable, "-m", "estim.cli.main", "report", "--results",
                           str(ROOT / "results"), "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return out


def _browse(page_file: Path, action):
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            errors: list[str] = []
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(page_file.as_uri())
            page.wait_for_load_state("load")
            return action(page), errors
        finally:
            browser.close()


def test_the_page_is_under_3_mb_and_loads_without_a_console_error(page_file):
    assert page_file.stat().st_size <= 3 * 1024 * 1024
    images, errors = _browse(page_file, lambda page: page.evaluate(
        "[...document.images].map(i => [i.alt, i.complete && i.naturalWidth > 0])"))
    assert not errors, errors
    assert images and all(ok for _, ok in images), [a for a, ok in images if not ok]


def test_two_in_page_links_land_on_their_sections(page_file):
    def follow(page):
        landed = []
        for selector in ('nav#toc a[href="#mosfet_saturation"]',
                         'table.summary a[href="#dipole_field"]'):
            page.click(selector)
            target = page.get_attribute(selector, "href")
            top = page.evaluate(f"document.getElementById('{target[1:]}')"
                                ".getBoundingClientRect().top")
            toc_visible = page.evaluate("document.getElementById('toc')"
                                        ".getBoundingClientRect().top")
            landed.append((page.evaluate("location.hash"), top, toc_visible))
        return landed

    landed, errors = _browse(page_file, follow)
    assert not errors, errors
    assert [hash_ for hash_, _, _ in landed] == ["#mosfet_saturation", "#dipole_field"]
    assert all(abs(top) < 5 for _, top, _ in landed), landed        # scrolled to the heading
    assert all(toc == 0 for _, _, toc in landed), landed            # the contents stay in view


def test_the_summary_counts_are_those_of_claims_csv(page_file):
    rows, errors = _browse(page_file, lambda page: page.evaluate(
        "[...document.querySelectorAll('table.summary tbody tr[data-name]')].map(r => "
        "[r.dataset.name, ...[...r.cells].slice(1).map(c => c.textContent)])"))
    assert not errors, errors
    checked = 0
    for name, holds, fails, undecided, against, findings, *_ in rows:
        assert int(against) + int(findings) == int(fails), name
        claims = ROOT / "results" / name / "claims.csv"
        if not claims.is_file():
            assert (holds, fails, undecided) == ("0", "0", "0"), name
            continue
        counts = pd.read_csv(claims)["verdict_family"].value_counts()     # after Holm
        assert [int(holds), int(fails), int(undecided)] == [
            int(counts.get(v, 0)) for v in ("holds", "fails", "undecided")], name
        checked += 1
    assert checked >= 20


def test_the_headline_is_in_view_and_every_wide_table_scrolls_in_its_own_box(page_file):
    """At 1,400 x 900: the headline table (one row per thesis or paper table, its counts
    those of claims.csv after Holm) is on screen before any scrolling, and no data table
    makes the page wider: each sits in a box of the page's width that scrolls it."""
    def look(page):
        head = page.evaluate("(() => { const r = document.querySelector('table.headline')"
                             ".getBoundingClientRect(); return [r.top, r.bottom]; })()")
        rows = page.evaluate("[...document.querySelectorAll('table.headline tbody tr')]"
                             ".map(r => [...r.cells].map(c => c.textContent))")
        widths = page.evaluate(
            "[...document.querySelectorAll('table.data')].map(t => [t.parentElement"
            ".className, t.parentElement.getBoundingClientRect().right, t.scrollWidth, "
            "t.parentElement.clientWidth])")
        page_width = page.evaluate("document.documentElement.scrollWidth")
        return head, rows, widths, page_width

    (head, rows, widths, page_width), errors = _browse(page_file, look)
    assert not errors, errors
    assert 0 <= head[0] and head[1] <= 900, head
    from estim.report.summary import HEADLINE

    assert len(rows) == len(HEADLINE)
    table, name, claim, holds, fails, undecided, cells, _, reading = rows[5]
    assert reading.startswith("holds in")
    df = pd.read_csv(ROOT / "results" / name / "claims.csv")
    family = df[df["claim"] == claim]["verdict_family"]
    assert [int(holds), int(fails), int(undecided), int(cells)] == [
        int((family == v).sum()) for v in ("holds", "fails", "undecided")] + [len(family)]
    assert page_width <= 1400
    assert widths and all(cls == "scroll" and right <= 1400 for cls, right, _, _ in widths)
    assert any(inner > box for _, _, inner, box in widths)      # some do scroll, inside


def test_rows_filter_and_sort_in_the_page(page_file):
    """The filter box above a data table keeps the rows that contain the words typed; a
    click on the summary's "fails" heading sorts each chapter's rows by it."""
    def act(page):
        index = page.evaluate(
            "[...document.querySelectorAll('input.filter')].findIndex(b => { const rows = "
            "[...b.nextElementSibling.querySelector('table').tBodies[0].rows]; return "
            "rows.some(r => r.textContent.includes('RLS')) && "
            "rows.some(r => !r.textContent.includes('RLS')); })")
        box = page.locator("input.filter").nth(index)
        table = (f"document.querySelectorAll('input.filter')[{index}].nextElementSibling"
                 ".querySelector('table')")
        before = page.evaluate(f"{table}.tBodies[0].rows.length")
        box.fill("RLS")
        shown = page.evaluate(f"[...{table}.tBodies[0].rows].filter(r => !r.hidden)"
                              ".map(r => r.textContent)")
        page.click("table.summary thead th:nth-child(3)")
        fails = page.evaluate(
            "[...document.querySelectorAll('table.summary tbody')].map(b => [...b.rows]"
            ".filter(r => r.dataset.name).map(r => parseFloat(r.cells[2].textContent)))")
        return before, shown, fails

    (before, shown, fails), errors = _browse(page_file, act)
    assert not errors, errors
    assert 0 < len(shown) < before and all("rls" in row.lower() for row in shown)
    assert fails and all(group == sorted(group) for group in fails)


def test_figures_are_readable_and_captioned_in_words(page_file):
    """Every figure is shown at least 600 pixels wide at 1,400 x 900, with a caption that
    says more than its file name."""
    def look(page):
        return page.evaluate(
            "[...document.querySelectorAll('figure')].map(f => [f.querySelector('img')"
            ".getBoundingClientRect().width, f.querySelector('figcaption').textContent, "
            "f.querySelector('figcaption code').textContent])")

    figures, errors = _browse(page_file, look)
    assert not errors, errors
    assert len(figures) >= 50
    assert all(width >= 600 for width, _, _ in figures), [f for f in figures if f[0] < 600]
    assert all(len(caption.replace(name, "").strip()) > 10 for _, caption, name in figures)
