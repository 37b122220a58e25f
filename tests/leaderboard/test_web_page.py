"""leaderboard/index.html in a real headless Chromium: no console error, sorting, filtering, hover, screenshot."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from benchmark.publish import report as leaderboard_report
from benchmark.publish.leaderboard import publish
from benchmark.store.profiles import get_profile
from benchmark.results.schema import Row

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install -e '.[test]')")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None or CHROMEDRIVER is None,
    reason="no headless browser: install Debian's chromium and chromium-driver (.ci/run does)")

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1280,1600")


def _rows(lens: str, profile: str, miou: float, psnr: dict[str, float], plate: float) -> list[Row]:
    common = {"lens": lens, "seed": 0, "profile": profile, "scenes": "synthetic"}
    rows = [Row(kind="utility", attack="utility", metrics={"miou": miou, "mean_acc": miou + 0.1}, **common)]
    threats = {"wiener-known-psf": "lens-access", "nafnet-known-pairs": "known-pairs"}
    for attack, value in psnr.items():
        row = Row(kind="restorer", attack=attack, restorer=attack, threat_model=threats[attack],
                  metrics={"psnr_db": value, "ssim": value / 40}, **common)
        row.set_interval("psnr_db", value - 0.4, value + 0.5, "bootstrap")
        rows.append(row)
    reader = Row(kind="reader", attack="lpdr", reader="lpdr", threat_model="sensor-access",
                 metrics={"plate_acc": plate}, **common)
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

    # Default view: one line per entry (threat model "any attacker"), as in the markdown table.
    rows = _visible_rows(browser)
    assert len(rows) == 4 and {r[4] for r in rows} == {"any attacker"}

    headers = browser.find_elements(By.CSS_SELECTOR, "#tradeoff thead th")
    miou_col = [h.text for h in headers].index("mIoU")
    headers[miou_col].click()
    ascending = [float(r[miou_col]) for r in _visible_rows(browser)]
    assert ascending == sorted(ascending) and ascending != [float(r[miou_col]) for r in rows]
    headers[miou_col].click()
    assert [float(r[miou_col]) for r in _visible_rows(browser)] == sorted(ascending, reverse=True)

    Select(browser.find_element(By.ID, "filter-profile")).select_by_value("smoke")
    rows = _visible_rows(browser)
    assert [(r[0], r[1]) for r in rows] == [("ideal", "smoke")]
    Select(browser.find_element(By.ID, "filter-profile")).select_by_value("*")

    # A threat model's lines show the worst case among its own attackers only.
    Select(browser.find_element(By.ID, "filter-threat")).select_by_value("lens-access")
    worst = {r[0] + "/" + r[1]: r[[h.text for h in headers].index("worst PSNR dB (attacker)")]
             for r in _visible_rows(browser)}
    assert worst["ideal/quick"] == "30.00 (wiener-known-psf)" and worst["gp/quick"] == "21.00 (wiener-known-psf)"
    points = [p for p in browser.find_elements(By.CSS_SELECTOR, "svg .point") if p.is_displayed()]
    # One point per entry in the PSNR chart; lens-access attackers read no plates, so none in the plate chart.
    assert len(points) == 4 and {p.get_attribute("data-threat") for p in points} == {"lens-access"}

    gp_point = next(p for p in points if p.get_attribute("data-lens") == "gp")
    ActionChains(browser).move_to_element(gp_point.find_element(By.TAG_NAME, "circle")).perform()
    tip = browser.find_element(By.ID, "tip")
    assert tip.is_displayed()
    assert "gp (quick" in tip.text and "wiener-known-psf" in tip.text and "[20.6, 21.5]" in tip.text

    shot = tmp_path / "leaderboard.png"
    assert browser.save_screenshot(str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 10_000
    errors = [entry for entry in browser.get_log("browser") if entry["level"] in ("SEVERE", "ERROR")]
    assert errors == []
