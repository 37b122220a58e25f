"""leaderboard/index.html in a real headless Chromium: no console error, sorting, filtering, hover, screenshot;
the first screen (takeaways and headline tables per profile, every column explained) with no headline cell
wrapped over two lines at 1400 px, on a test board and on the published leaderboard."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import publish
from benchmark.store.profiles import get_profile
from benchmark.results.entries import LEADERBOARD
from benchmark.results.schema import Row, Units

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install -e '.[test]')")
pytestmark = [pytest.mark.slow, pytest.mark.skipif(  # slow: drives a headless Chromium
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="no headless browser: install Debian's chromium and chromium-driver (.ci/run does)")]

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1280,1600")


def _rows(lens: str, profile: str, miou: float, psnr: dict[str, float], plate: float) -> list[Row]:
    common = {"lens": lens, "seed": 0, "profile": profile, "scenes": "synthetic"}
    # Per-scene intersections and unions (two classes) giving mIoU `miou`; 40 plates of which `plate` are read.
    scenes = [f"s{i}" for i in range(8)]
    utility = Units("scene", "synthetic/val/0/", tuple(scenes),
                    {"intersection": tuple((round(100 * miou) + i % 3, 50) for i in range(8)),
                     "union": tuple((100, 100) for _ in scenes)})
    rows = [Row(kind="utility", attack="utility", metrics={"miou": miou, "mean_acc": miou + 0.1}, units=utility,
                **common)]
    threats = {"wiener-known-psf": "lens-access", "nafnet-known-pairs": "known-pairs"}
    for attack, value in psnr.items():
        per_scene = tuple(value + (0.3 if i % 2 else -0.3) for i in range(8))  # mean `value`
        row = Row(kind="restorer", attack=attack, restorer=attack, threat_model=threats[attack],
                  metrics={"psnr_db": value, "ssim": value / 40}, **common,
                  units=Units("scene", "synthetic/val/0/", tuple(scenes), {"psnr_db": per_scene}))
        row.set_interval("psnr_db", value - 0.4, value + 0.5, "bootstrap")
        rows.append(row)
    read = round(40 * plate)
    plates = Units("plate", "synthetic/val/0/", tuple(f"s{i // 5}#{i % 5}" for i in range(40)),
                   {"correct": tuple(int(i < read) for i in range(40)), "char_errors": tuple(0 if i < read else 2
                                                                                             for i in range(40))})
    reader = Row(kind="reader", attack="lpdr", reader="lpdr", threat_model="sensor-access",
                 metrics={"plate_acc": read / 40}, units=plates, **common)
    reader.set_interval("plate_acc", max(0.0, plate - 0.05), plate + 0.05, "wilson")
    return rows + [reader]


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    board = tmp_path_factory.mktemp("board")
    (board / "entries").mkdir()
    rows = (_rows("gp", "quick", 0.30, {"wiener-known-psf": 21.0, "nafnet-known-pairs": 24.0}, 0.05)
            + _rows("ideal", "quick", 0.40, {"wiener-known-psf": 30.0, "nafnet-known-pairs": 28.0}, 0.60)
            + _rows("defocus", "quick", 0.35, {"wiener-known-psf": 25.0}, 0.20))
    publish(rows, get_profile("quick").to_dict(), {}, board)
    publish(_rows("ideal", "smoke", 0.05, {"wiener-known-psf": 27.0}, 0.4), get_profile("smoke").to_dict(), {}, board)
    written = leaderboard_report.render(board)
    assert board / "index.html" in written
    return board / "index.html"


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    yield driver
    driver.quit()


def _open_details(driver) -> None:
    from selenium.webdriver.common.by import By
    details = driver.find_element(By.ID, "more")
    if details.get_attribute("open") is None:
        details.find_element(By.TAG_NAME, "summary").click()


def _visible_rows(driver) -> list[list[str]]:
    from selenium.webdriver.common.by import By
    return [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
            for tr in driver.find_elements(By.CSS_SELECTOR, "#tradeoff tbody tr") if tr.is_displayed()]


def test_page_is_self_contained(page):
    text = page.read_text()
    assert "http://" not in text.replace('xmlns="http://www.w3.org/2000/svg"', "") and "https://" not in text
    assert "<script src" not in text and "<link rel=\"stylesheet\"" not in text


def test_loads_sorts_filters_hovers_and_screenshots(page, browser, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    browser.get(page.as_uri())
    assert browser.title == "Privacy Lens Bench leaderboard"
    errors = [entry for entry in browser.get_log("browser") if entry["level"] in ("SEVERE", "ERROR")]
    assert errors == []

    _open_details(browser)
    # Default view: one line per entry (threat model "any attacker"), as in the markdown table.
    rows = _visible_rows(browser)
    assert len(rows) == 4 and {r[4] for r in rows} == {"any attacker"}

    headers = browser.find_elements(By.CSS_SELECTOR, "#tradeoff thead th")
    miou_col = [h.text for h in headers].index("mIoU [95 %]")
    headers[miou_col].click()
    miou = lambda rows: [float(r[miou_col].split()[0]) for r in rows]  # noqa: E731  "0.300 (no per-scene ...)"
    ascending = miou(_visible_rows(browser))
    assert ascending == sorted(ascending) and ascending != miou(rows)
    headers[miou_col].click()
    assert miou(_visible_rows(browser)) == sorted(ascending, reverse=True)

    Select(browser.find_element(By.ID, "filter-profile")).select_by_value("smoke")
    rows = _visible_rows(browser)
    assert [(r[0], r[1]) for r in rows] == [("ideal", "smoke")]
    Select(browser.find_element(By.ID, "filter-profile")).select_by_value("*")

    # A threat model's lines show the worst case among its own attackers only.
    Select(browser.find_element(By.ID, "filter-threat")).select_by_value("lens-access")
    worst = {r[0] + "/" + r[1]: r[[h.text for h in headers].index("worst PSNR dB [95 %] (attacker)")]
             for r in _visible_rows(browser)}
    assert worst["ideal/quick"].startswith("30.00 [") and worst["ideal/quick"].endswith("(wiener-known-psf)")
    assert worst["gp/quick"].startswith("21.00 [") and worst["gp/quick"].endswith("(wiener-known-psf)")
    points = [p for p in browser.find_elements(By.CSS_SELECTOR, "svg .point") if p.is_displayed()]
    # One point per entry in the PSNR chart; lens-access attackers read no plates, so none in the plate chart.
    assert len(points) == 4 and {p.get_attribute("data-threat") for p in points} == {"lens-access"}

    gp_point = next(p for p in points if p.get_attribute("data-lens") == "gp")
    ActionChains(browser).move_to_element(gp_point.find_element(By.TAG_NAME, "circle")).perform()
    tip = browser.find_element(By.ID, "tip")
    assert tip.is_displayed()
    # The chart's figure is the table's: the ensemble of the view's restorers (wiener alone for lens access).
    assert "gp (quick" in tip.text and "ensemble of 1 restorer\n" in tip.text and "21 dB [" in tip.text

    shot = tmp_path / "leaderboard.png"
    assert browser.save_screenshot(str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 10_000
    errors = [entry for entry in browser.get_log("browser") if entry["level"] in ("SEVERE", "ERROR")]
    assert errors == []


# Lines of text each headline cell spans: the distinct tops of its text's line boxes (a Range over its
# contents has one client rect per line fragment). Not the cell's height: a cell is as tall as its row,
# so one wrapped cell would make its neighbours look wrapped too.
_CELL_LINES = """
return Array.prototype.map.call(document.querySelectorAll(arguments[0]), function (cell) {
  var range = document.createRange();
  range.selectNodeContents(cell);
  var tops = [];
  Array.prototype.forEach.call(range.getClientRects(), function (r) {
    if (r.width > 0 && !tops.some(function (t) { return Math.abs(t - r.top) < 2; })) { tops.push(r.top); }
  });
  return [cell.textContent, tops.length];
});
"""
HEADLINE_CELLS = "table.headline th, table.headline td"


def _wrapped(driver) -> list[tuple[str, int]]:
    return [(text, lines) for text, lines in driver.execute_script(_CELL_LINES, HEADLINE_CELLS) if lines > 1]


def _at_1400(driver, uri: str) -> None:
    driver.set_window_size(1400, 1000)
    driver.get(uri)
    assert driver.execute_script("return window.innerWidth") <= 1400


@pytest.mark.parametrize("which", ["test board", "published"])
def test_first_screen_answers_the_question_without_wrapping(page, browser, which):
    from selenium.webdriver.common.by import By

    path = page if which == "test board" else LEADERBOARD / "index.html"
    _at_1400(browser, path.as_uri())
    profiles = list(dict.fromkeys(t.get_attribute("data-profile")
                                  for t in browser.find_elements(By.CSS_SELECTOR, "table.headline")))
    assert {"quick", "smoke"} <= set(profiles)  # quick and smoke in tables of their own
    for table in browser.find_elements(By.CSS_SELECTOR, "table.headline"):
        assert table.is_displayed()
        heads = [th.text for th in table.find_elements(By.TAG_NAME, "th")]
        assert [h.split(" [")[0] for h in heads] == ["lens", "mIoU", "plates read %", "ceiling gap pt", "seeds"]
        # Every column explained: a tooltip on its header and an entry in the legend.
        titles = [th.get_attribute("title") for th in table.find_elements(By.TAG_NAME, "th")]
        assert all(len(t) > 20 for t in titles)
        rows = table.find_elements(By.CSS_SELECTOR, "tbody tr")
        assert rows and all(len(r.find_elements(By.TAG_NAME, "td")) == len(heads) for r in rows)
        # Its lines are its profile's entries only; the table fits the 1400 px window.
        right = browser.execute_script("return arguments[0].getBoundingClientRect().right", table)
        assert right <= browser.execute_script("return document.documentElement.clientWidth")
    legend = browser.find_element(By.CSS_SELECTOR, "dl.legend").text
    assert all(h in legend for h in ("lens", "mIoU [95 %]", "plates read % [95 %]", "ceiling gap pt [95 %]", "seeds"))
    # A takeaway per profile, generated (it names a lens of that profile), and its chart of utility against the
    # plates the ensemble reads beside its table; the long tables are one click away.
    for section in browser.find_elements(By.CSS_SELECTOR, "section.profile"):
        chart = section.find_element(By.CSS_SELECTOR, ".first svg")
        assert chart.is_displayed() and "plates read by the ensemble" in chart.get_attribute("aria-label")
        takeaway = section.find_element(By.CLASS_NAME, "takeaway").text
        lenses = {r.find_element(By.TAG_NAME, "td").text for r in section.find_elements(By.CSS_SELECTOR, "tbody tr")}
        assert takeaway.startswith("Takeaway.") and any(f" {lens} " in takeaway or f" {lens}," in takeaway
                                                        for lens in lenses)
    assert not browser.find_element(By.ID, "tradeoff").is_displayed()
    assert browser.find_element(By.CSS_SELECTOR, "#more > summary").is_displayed()
    # No headline cell wraps over two lines at 1400 px.
    assert _wrapped(browser) == []


def test_the_wrap_check_sees_a_wrapped_cell(page, browser):
    """The check above is not vacuous: the mIoU column of a headline table squeezed until it wraps is reported."""
    _at_1400(browser, page.as_uri())
    assert _wrapped(browser) == []
    squeezed = browser.execute_script(
        "var table = document.querySelector('table.headline'); table.style.width = '1px';"
        "var cells = table.querySelectorAll('td:nth-child(2), th:nth-child(2)');"
        "cells.forEach(function (c) { c.style.whiteSpace = 'normal'; });"
        "return Array.prototype.map.call(cells, function (c) { return c.textContent; });")
    wrapped = _wrapped(browser)
    assert wrapped and {text for text, _ in wrapped} <= set(squeezed) and all(lines >= 2 for _, lines in wrapped)
