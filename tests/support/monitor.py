"""The monitor's screen driven headless over a replayed log, and the log's own last state
decoded by stock cantools: what the monitor's tests and the HIL run's replay check share."""

from __future__ import annotations

import asyncio
import time

import can
import cantools
import pytest
from rich.console import Console

from hil.monitor.app import MonitorApp
from hil.monitor.sources import ReplaySource, check_log
from hil.monitor.view import BusView
from protocol.codec import CODECS
from protocol.dbc import dbc_path


def text_of(widget) -> str:
    """What a Static shows, as plain text."""
    console = Console(width=200, record=True)
    console.print(widget.content)
    return console.export_text()


def replay(path, speed: float = 0.0, until=None) -> MonitorApp:
    """Replay `path` through the app headless; returns it once the log is through."""
    view = BusView()
    app = MonitorApp(view, ReplaySource(view, check_log(str(path)), speed), "test")

    async def drive():
        async with app.run_test(size=(160, 48)) as pilot:
            deadline = time.monotonic() + 120
            while not app.source.done.is_set() and time.monotonic() < deadline:
                await pilot.pause(0.05)
            app.redraw()
            await pilot.pause()
            app.texts = {key: text_of(app.query_one(f"#{key}")) for key in ("controller", "legs", "emcy")}
            if until is not None:
                await until(app, pilot)
    asyncio.run(drive())
    return app


def log_oracle(path) -> dict:
    """The log's last CTRL_STATUS and LEG_STATE_1, decoded by stock cantools."""
    db = cantools.database.load_file(str(dbc_path()))
    last = {}
    with can.LogReader(str(path)) as reader:
        for msg in reader:
            name = {CODECS["CTRL_STATUS"].frame_id: "CTRL_STATUS",
                    CODECS["LEG_STATE_1"].frame_id: "LEG_STATE_1"}.get(msg.arbitration_id)
            if name:
                last[name] = db.decode_message(msg.arbitration_id, msg.data, decode_choices=True)
    return last


def assert_replay_shows_the_log(path) -> None:
    """The screen at the end of a replay shows the log's last state, fault and leg 1."""
    app = replay(path)
    oracle = log_oracle(path)
    shown = app.texts["controller"]
    assert str(oracle["CTRL_STATUS"]["STATE"]) in shown and str(oracle["CTRL_STATUS"]["FAULT_CODE"]) in shown
    legs = app.texts["legs"]
    assert f"{oracle['LEG_STATE_1']['POSITION']:.2f}" in legs
    assert app.shown.legs[0].position_m * 1e3 == pytest.approx(oracle["LEG_STATE_1"]["POSITION"], abs=1e-6)
