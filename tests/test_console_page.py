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


#: one headless chromium for the module's tests (each test gets a context of its own)
_SHARED: dict = {}


@pytest.fixture(scope="module", autouse=True)
def _shared_browser():
    """Close the module's chromium after its last test."""
    yield
    if _SHARED:
        _SHARED.pop("browser").close()
        _SHARED.pop("pw").stop()


@contextlib.contextmanager
def browser_on(hub):
    """The served hub and the module's headless chromium; yields (port, tabs, js_errors)."""
    sync_api = _sync_api()
    if not _SHARED:
        pw = sync_api.sync_playwright().start()
        _SHARED["pw"] = pw
        _SHARED["browser"] = pw.chromium.launch(
            executable_path=str(CHROMIUM), args=["--no-sandbox"]
        )
    errors: list[str] = []
    with running(hub) as port:
        tabs = _Tabs(_SHARED["browser"])
        try:
            yield port, tabs, errors
        finally:
            tabs.close()
    assert errors == []  # the page's script ran without an exception


class _Tabs:
    """``new_page`` of the shared chromium, each page in a context of its own (closed at
    the end of the test)."""

    def __init__(self, browser) -> None:
        self.browser, self.contexts = browser, []

    def new_page(self, **options):
        context = self.browser.new_context(**options)
        self.contexts.append(context)
        return context.new_page()

    def close(self) -> None:
        for context in self.contexts:
            context.close()


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


def test_time_scale_steps_through_one_and_quick_presses_each_count() -> None:
    """+ and − step through 0.05 … 0.5, 1, 2, 5 … 20: three quick + presses go 1 → 10,
    though no frame arrives between them, two − back to 2, one more to 1 (the real-time
    scale is reachable again), − then + from 1 gives 0.5 then 1, and the ends hold."""
    hub = fake_hub()
    pace = hub.session.pace
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        for _ in range(3):
            page.keyboard.press("+")
        assert _until(lambda: pace.scale == 10.0), pace.scale
        page.keyboard.press("-")
        page.keyboard.press("-")
        assert _until(lambda: pace.scale == 2.0), pace.scale
        page.keyboard.press("-")
        assert _until(lambda: pace.scale == 1.0), pace.scale
        page.keyboard.press("-")
        assert _until(lambda: pace.scale == 0.5), pace.scale
        page.keyboard.press("+")
        assert _until(lambda: pace.scale == 1.0), pace.scale
        assert _until(lambda: page.text_content("#scale") == "1")
        for _ in range(12):
            page.keyboard.press("+")
        assert _until(lambda: pace.scale == 20.0), pace.scale
        for _ in range(12):
            page.keyboard.press("-")
        assert _until(lambda: pace.scale == 0.05), pace.scale


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


# --------------------------------------------------------------- letting go, frames, layout
def test_closing_the_driving_tab_mid_press_returns_u0_to_zero() -> None:
    """Dead-man's handle: the driving tab closes while → is held; the command goes back
    to 0 (the server's release when the socket closes) and lands (the shaped u0 ramps
    to 0 from there); a
    tab that reloads mid-press does the same, and a new driver starts from 0."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.keyboard.down("ArrowRight")
        assert _until(lambda: tuple(loop.target.u0) == (2.0,))
        time.sleep(0.8)  # held beyond the dead-man time: the page's keepalives hold it
        assert tuple(loop.target.u0) == (2.0,)
        page.close()
        assert _until(lambda: tuple(loop.target.u0) == (0.0,), 1.0)
        assert _until(lambda: loop.settings.u0[0] == 0.0, 1.0)  # landed: ramping to 0
        page = _open(browser, port, errors)
        assert tuple(loop.target.u0) == (0.0,)
        page.keyboard.down("ArrowLeft")
        assert _until(lambda: tuple(loop.target.u0) == (-2.0,))
        page.reload()
        assert _until(lambda: tuple(loop.target.u0) == (0.0,), 1.0)


@pytest.mark.parametrize(
    "leave",
    [
        "window.dispatchEvent(new Event('blur'))",
        "Object.defineProperty(document, 'hidden', {value: true, configurable: true});"
        " document.dispatchEvent(new Event('visibilitychange'))",
    ],
    ids=["blur", "hidden"],
)
def test_a_page_that_loses_focus_or_hides_releases_its_keys(leave: str) -> None:
    """A held key is released when the page loses focus or is hidden: u0 goes to 0 and
    stays there (no keepalive of the old command follows)."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.keyboard.down("ArrowRight")
        assert _until(lambda: tuple(loop.target.u0) == (2.0,))
        page.evaluate(leave)
        assert _until(lambda: tuple(loop.target.u0) == (0.0,), 1.0)
        time.sleep(0.5)
        assert tuple(loop.target.u0) == (0.0,)


def test_a_long_integrator_call_shows_busy_and_stopped_frames_show_no_frames() -> None:
    """An integrator call of 1.2 s (on the loop's own thread) does not stop the frames:
    the page gets one at least every 0.5 s, says BUSY, then ok again. When frames
    really stop (the server sends none for 1.5 s) the page says so within ~1 s,
    instead of 'ok'."""
    hub = fake_hub()
    loop = hub.session.loop
    plain = loop.integrate
    slow = {"at": None}

    def integrate(x0, t_out, breaks, attempt=0):
        if slow["at"] is not None and t_out[0] >= slow["at"]:
            slow["at"] = None
            time.sleep(1.2)
        return plain(x0, t_out, breaks, attempt)

    loop.integrate = integrate
    script = "window.__gaps = []; window.__prev = null; window.__busy = false;"
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors, script=script)
        page.wait_for_function("last && last.t > 0.5")
        page.evaluate(
            """() => { setInterval(() => {
                 const h = document.getElementById('health').textContent;
                 if (h.startsWith('BUSY')) window.__busy = true; }, 50);
               ws.addEventListener('message', () => { const now = performance.now();
                 if (window.__prev !== null) window.__gaps.push(now - window.__prev);
                 window.__prev = now; }); }"""
        )
        slow["at"] = loop.t + 0.1
        assert _until(lambda: slow["at"] is None, 3.0)
        time.sleep(1.5)
        assert page.evaluate("window.__busy")
        assert max(page.evaluate("window.__gaps")) < 500
        assert page.text_content("#health") == "ok"
        real = hub._broadcast
        hub._broadcast = lambda frame: None  # the server stops sending frames
        time.sleep(1.4)
        assert page.text_content("#health") == "NO FRAMES"
        assert "NO FRAMES for" in page.text_content("#stale") and page.is_visible("#stale")
        hub._broadcast = real
        page.wait_for_function("document.getElementById('health').textContent === 'ok'")
        assert not page.is_visible("#stale")


def test_a_cut_that_breaks_assumption_1_is_refused_with_the_reason() -> None:
    """Follower 1 hears only the leader (followers 2 and 3 hear the leader through it):
    clicking its 'leader' link is refused, the page shows why (Assumption 1, the
    followers it would cut off), and nothing changes; cutting 3 ← 2 (3 still hears 1)
    is accepted."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.click("button[data-link='1,0']")
        page.wait_for_function("document.getElementById('errors').textContent.includes('link')")
        text = page.text_content("#errors")
        assert "Assumption 1" in text and "followers 1, 2, 3 unreachable" in text, text
        time.sleep(0.3)
        assert loop.target.weights[(0, -1)] == 1.0 and loop.changes == []
        page.click("button[data-link='3,2']")
        assert _until(lambda: [c.kind for c in loop.changes] == ["link"])
        assert loop.settings.weights[(2, 1)] == 0.0


def test_a_stick_sweeping_at_half_a_hertz_never_fills_the_ramp_slots() -> None:
    """A gamepad stick sweeping ±1 at 0.5 Hz for 3 s sends a new command every frame: no
    frame waits for a ramp slot, and the shaped u0 the loop runs stays within 0.5 u_max
    of the shaping of every command from the time it arrived. Bound: each change lands
    at most r/12 + two frames (0.15 s at r = 1 s) after it arrives; the commands of one
    rise time vary by at most 2 u_max in total and S' <= 1.5/r, so the two differ by at
    most 2 · 1.5 · 0.15 = 0.45 u_max. Behind 12 full slots a change waited up to 1.6 s
    (most of u_max)."""
    hub = fake_hub()
    loop = hub.session.loop
    asked: list[tuple[float, float]] = []
    ran: list[tuple[float, float]] = []
    set_u0, advance = loop.set_u0, loop.advance

    def record_set(values):
        asked.append((loop.t, values[0]))
        set_u0(values)

    def record_advance(quanta):
        out = advance(quanta)
        ran.append((loop.t, float(loop.u0_at(loop.t)[0])))
        return out

    loop.set_u0, loop.advance = record_set, record_advance
    pad = """navigator.getGamepads = () => [{id: 'sweep', buttons: [],
      axes: [Math.sin(Math.PI * performance.now() / 1000), 0]}];"""
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors, script=pad)
        page.evaluate(
            "window.__full = 0; setInterval(() => { if (last && last.slots_full) window.__full++; }, 30)"
        )
        time.sleep(3.0)
        assert page.evaluate("window.__full") == 0
        page.close()
    assert len(asked) > 45  # a command (nearly) every frame
    r, t0 = loop.rise, asked[0][0]
    times = np.array([t for t, _ in asked])
    steps = np.diff(np.array([0.0] + [v for _, v in asked]))

    def ideal(t: float) -> float:  # every command shaped from when it arrived
        x = np.clip((t - times) / r, 0.0, 1.0)
        return float(np.sum(steps * x * x * (3 - 2 * x)))

    late = [(t, u) for t, u in ran if t0 + 1.0 < t < asked[-1][0]]
    lag = max(abs(u - ideal(t)) for t, u in late)
    print(f"shaped u0 against the shaping from each arrival: {lag / loop.limits.u_max:.3f} u_max")
    assert len(late) > 25 and lag < 0.5 * loop.limits.u_max, lag


def test_peak_effort_is_shown_with_a_verdict() -> None:
    """The header gives the largest |u_i| since t = 1 s and whether it is within the
    bound (1e3); a follower whose |u| reaches 5e3 turns the verdict and its table cell."""
    hub = fake_hub()
    loop = hub.session.loop
    plain = loop.signals
    big = {"on": False}

    def signals(x):
        s = plain(x)
        if big["on"]:
            s["unorm"] = [s["unorm"][0], 5e3, s["unorm"][2]]
        return s

    loop.signals = signals
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.wait_for_function("last && last.t > 1.3")
        assert page.text_content("#peak").endswith("≤ 1000: ok")
        big["on"] = True
        page.wait_for_function("document.getElementById('peak').textContent.includes('above')")
        assert "5.0e+3 > 1000: 1 follower above the bound" in page.text_content("#peak")
        assert page.text_content("#pk1") == "5.0e+3"
        assert page.get_attribute("#pk1", "class") == "alarm"
        assert page.get_attribute("#pk0", "class") == ""


def test_the_page_fits_800_pixels_and_its_plots_name_units_and_time_axis() -> None:
    """At 800 px wide nothing needs a horizontal scroll: the world view, both plots and the
    follower table fit, and a link button of the last follower is clickable and acts.
    Every plot draws its time axis label, and each plot's title names its units."""
    hub = fake_hub()
    loop = hub.session.loop
    texts = """window.__texts = [];
      const _fill = CanvasRenderingContext2D.prototype.fillText;
      CanvasRenderingContext2D.prototype.fillText = function (t, x, y) {
        window.__texts.push([this.canvas.id, String(t)]); return _fill.apply(this, arguments); };"""
    with browser_on(hub) as (port, browser, errors):
        page = browser.new_page(viewport={"width": 800, "height": 700})
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.add_init_script(texts)
        page.goto(f"http://127.0.0.1:{port}/")
        page.wait_for_function("document.getElementById('role').textContent.startsWith('driver')")
        page.wait_for_function("last && last.t > 1.2")
        assert page.evaluate("document.documentElement.scrollWidth") <= 800
        for sel in ("#world", "#plot_et", "#plot_est", "#followers"):
            box = page.locator(sel).bounding_box()
            assert box["x"] >= 0 and box["x"] + box["width"] <= 800, (sel, box)
        page.click("button[data-link='3,2']")
        assert _until(lambda: loop.settings.weights[(2, 1)] == 0.0)
        drawn = page.evaluate("window.__texts")
        for plot in ("plot_et", "plot_est"):
            assert [plot, "simulated time t (s)"] in drawn
        titles = page.text_content(".plots")
        assert "position units of p" in titles and "units of the leader" in titles


def test_r_asks_before_it_resets() -> None:
    """r opens a confirmation: dismissed, the run goes on; accepted, it resets to t = 0."""
    hub = fake_hub()
    loop = hub.session.loop
    with browser_on(hub) as (port, browser, errors):
        page = _open(browser, port, errors)
        page.wait_for_function("last && last.t > 1.0")
        answers = iter([False, True])
        seen: list[str] = []

        def on_dialog(d):
            seen.append(d.message)
            d.accept() if next(answers) else d.dismiss()

        page.on("dialog", on_dialog)
        page.keyboard.press("r")
        time.sleep(0.4)
        assert len(seen) == 1 and "Reset" in seen[0] and loop.t > 1.0
        page.keyboard.press("r")
        assert _until(lambda: loop.t < 0.5) and len(seen) == 2
