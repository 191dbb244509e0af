"""The console page in headless chromium (Playwright) on the stand-in loop.

Each test serves :class:`console_fake.FakeLoop` through the real server and drives the
page as an operator would (keys, buttons, a second tab, a gamepad the page is given),
then checks what the server received and what the page shows. The compiled closed
loop's page test is in ``tests/test_console_replay.py``.
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import numpy as np
import pytest
from console_fake import fake_hub, running

CHROMIUM = Path("/usr/bin/chromium")


def _sync_api():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is missing (make chromium needs apt-get as root)")
    return sync_api


@contextlib.contextmanager
def browser_on(hub):
    """The served hub and a headless chromium; yields (port, browser, js_errors)."""
    sync_api = _sync_api()
    errors: list[str] = []
    with running(hub) as port, sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        try:
            yield port, browser, errors
        finally:
            browser.close()
    assert errors == []  # the page's script ran without an exception


def _open(browser, port: int, errors: list[str], role: str = "driver", script: str = ""):
    page = browser.new_page(viewport={"width": 1200, "height": 760})
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    if script:
        page.add_init_script(script)
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_function(
        f"document.getElementById('role').textContent.startsWith('{role}')", timeout=10_000
    )
    return page


def _until(cond, seconds: float = 5.0) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return cond()


def test_planar_leader_arrows_and_gamepad() -> None:
    """Two inputs: → and ← drive u0[1], ↑ and ↓ drive u0[2], each ±u_max = α/√2; holding
    ↑ moves the leader's y0 up and not sideways; a gamepad's stick (x 0.5, y −0.8: pushed
    up) sets u0 = (0.5, 0.8) u_max; the page says which key drives which input."""
    hub = fake_hub(p=2)
    loop = hub.session.loop
    a = loop.limits.u_max
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        assert "2 inputs" in page.text_content("#inputs")
        page.keyboard.down("ArrowUp")
        assert _until(lambda: tuple(loop.target.u0) == (0.0, a))
        page.keyboard.down("ArrowRight")
        assert _until(lambda: tuple(loop.target.u0) == (a, a))
        page.keyboard.up("ArrowRight")
        assert _until(lambda: tuple(loop.target.u0) == (0.0, a))
        time.sleep(1.5)
        page.keyboard.up("ArrowUp")
        page.keyboard.down("ArrowDown")
        assert _until(lambda: tuple(loop.target.u0) == (0.0, -a))
        page.keyboard.up("ArrowDown")
        assert _until(lambda: tuple(loop.target.u0) == (0.0, 0.0))
        y0 = loop.leader_output(loop.x)
        assert y0[1] > 0.2 and abs(y0[0]) < 0.5 * y0[1]  # mostly up: ↑ was held longest
        page.close()
        pad = "navigator.getGamepads = () => [{id: 'test pad', axes: [0.5, -0.8], buttons: []}];"
        page = _open(browser, port, errors, script=pad)
        assert _until(lambda: np.allclose(loop.target.u0, [0.5 * a, 0.8 * a], atol=1e-3))
        assert "test pad" in page.text_content("#pads")


def test_one_input_leader_keeps_every_arrow_and_says_so() -> None:
    """One input: → and ↑ give +α, ← and ↓ give −α, and the page says the leader moves
    on a line."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        assert "one input" in page.text_content("#inputs")
        for key, want in (("ArrowUp", 2.0), ("ArrowDown", -2.0), ("ArrowRight", 2.0)):
            page.keyboard.down(key)
            assert _until(lambda want=want: tuple(loop.target.u0) == (want,)), key
            page.keyboard.up(key)
            assert _until(lambda: tuple(loop.target.u0) == (0.0,))


def test_quick_time_scale_presses_each_count() -> None:
    """Three quick + presses double the scale three times (1 → 8), two − halve it twice,
    though no frame arrives between the presses."""
    hub = fake_hub()
    pace = hub.session.pace
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.keyboard.press("+")
        page.keyboard.press("+")
        page.keyboard.press("+")
        assert _until(lambda: pace.scale == 8.0), pace.scale
        page.keyboard.press("-")
        page.keyboard.press("-")
        assert _until(lambda: pace.scale == 2.0), pace.scale
        assert _until(lambda: page.text_content("#scale") == "2")


def test_a_watcher_takes_over_with_the_drive_button() -> None:
    """A second tab watches: its drive button is shown but disabled while another page
    drives, its key presses get an error naming that button; when the driver's tab
    closes the button is enabled, and pressing it makes the tab drive."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        driver = _open(browser, port, errors)
        watcher = _open(browser, port, errors, role="watcher")
        button = watcher.locator("#drive")
        assert button.is_visible() and button.is_disabled()
        assert button.text_content() == "drive"
        watcher.wait_for_function("document.getElementById('errors').textContent.length > 0")
        text = watcher.text_content("#errors")  # its drive on opening was refused
        assert "drive: another page drives (the drive button takes over once it closes)" in text
        watcher.keyboard.down("ArrowRight")
        watcher.wait_for_function(
            "document.getElementById('errors').textContent.includes('this page watches')"
        )
        text = watcher.text_content("#errors")
        assert "u0: this page watches (press drive to take over when no page drives)" in text
        watcher.keyboard.up("ArrowRight")
        assert tuple(loop.target.u0) == (0.0,)
        driver.close()
        watcher.wait_for_function("!document.getElementById('drive').disabled")
        button.click()
        watcher.wait_for_function(
            "document.getElementById('role').textContent.startsWith('driver')"
        )
        watcher.keyboard.down("ArrowRight")
        assert _until(lambda: tuple(loop.target.u0) == (2.0,))
        assert not button.is_visible()


def test_a_refused_replay_is_shown_with_the_servers_reason() -> None:
    """A save whose replay the server refuses shows the record's folder and the reason
    the server gave, marked as refused (not as a saved replay)."""
    reason = "the replay is not a valid scenario: graph: follower 1 cannot be reached"

    def recorder(snap) -> dict:
        reply = {"folder": "out/x/record-1", "scenario": "", "rows": snap.rows, "t_end": 0.5}
        return {**reply, "reason": reason}

    hub = fake_hub(recorder=recorder)
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.click("#save")
        page.wait_for_function("document.getElementById('saved').textContent.length > 0")
        assert page.get_attribute("#saved", "class") == "refused"
        text = page.text_content("#saved")
        assert "replay refused: " + reason in text and "out/x/record-1" in text


def test_plots_have_a_time_axis_and_a_spike_does_not_flatten_them() -> None:
    """Three frames with ‖e_t1‖ = 1e6 among values of order 1: the plot's scale stays at
    the 98th percentile (below 100), the clip is marked with the spike's size, and the
    time axis has a tick every simulated second of the window."""
    hub = fake_hub()
    loop = hub.session.loop
    plain = loop.signals

    spikes = [0, np.inf]  # frames left to spike, from this time on

    def spiky(x):
        s = plain(x)
        if loop.t >= spikes[1] and spikes[0] > 0:
            spikes[0] -= 1
            s["et"] = [1e6, *s["et"][1:]]
        return s

    loop.signals = spiky
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        t_open = loop.t
        spikes[:] = [3, t_open + 0.5]  # three frames (a page may miss one, not three)
        page.wait_for_function(f"window.__drawn.plots.plot_et && last && last.t > {t_open + 2.5}")
        plot = page.evaluate("window.__drawn.plots.plot_et")
        assert plot["clipped"] and plot["max"] == 1e6 and plot["top"] < 100
        assert plot["ticks"] == list(range(int(np.ceil(max(plot["t0"], 0))), int(plot["t1"]) + 1))
        assert len(plot["ticks"]) >= 2


@pytest.mark.parametrize(
    ("raw", "line"),
    [
        ('{"type": "u0", "value": [%s]}' % ("9" * 400), "value[0]: a 400-digit number is out"),
        ('{"type": "u0", "value": [NaN]}', "value[0]: NaN is not a finite number"),
        ('{"type": "u0", "value": [-Infinity]}', "value[0]: -Infinity is not a finite number"),
        ('{"type": "u0", "value": [2.0000001]}', "value[0]: 2.0000001 is out of range [-2, 2]"),
        ('{"type": "u0", "value": [1], "speed": 2}', "'speed': unknown field of a 'u0' message"),
    ],
)
def test_bad_numbers_sent_by_the_page_get_one_line_naming_the_field(raw: str, line: str) -> None:
    """The page's socket carries the raw text; the error the page shows is one line that
    names the field; the loop did not change."""
    hub = fake_hub()
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.evaluate("(raw) => ws.send(raw)", raw)
        page.wait_for_function("document.getElementById('errors').textContent.length > 0")
        shown = page.text_content("#errors").strip().splitlines()
        assert len(shown) == 1 and line in shown[0], shown
        assert hub.session.loop.changes == [] and tuple(hub.session.loop.target.u0) == (0.0,)


def test_the_page_shows_a_recovery_and_a_hold_and_resume_retries() -> None:
    """An attempt that fails once is recovered: the header counts the restart and the
    events list names the failure and the recovery. An attempt that always fails holds
    the loop: the banner gives the reason, and its Resume button (once the cause is
    gone) runs the loop on from the held time, not from t = 0."""
    hub = fake_hub()
    loop = hub.session.loop
    loop.fail_at, loop.fail_attempts = 0.505, 1  # inside the step from 0.5 s
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.wait_for_function("last && last.t > 0.8")
        assert "1 restart after a failure" in page.text_content("#recoveries")
        events = page.text_content("#events")
        assert "failure: fake failure at t = 0.5" in events and "recovered" in events
        t_hold = round(loop.t + 0.5, 2)
        loop.fail_at, loop.fail_attempts = t_hold + 0.005, 10**9  # inside the step from t_hold
        page.wait_for_function("document.getElementById('banner').style.display === 'block'")
        assert page.text_content("#health") == "HELD"
        assert f"held at t = {t_hold:g} s" in page.text_content("#why")
        loop.fail_at = None
        page.click("#retry")
        page.wait_for_function("document.getElementById('banner').style.display === 'none'")
        page.wait_for_function(f"last && last.t > {t_hold + 0.3}")
        assert page.text_content("#health") == "ok"
