"""The monitor's screen (Textual): redrawn ten times a second from a `Snapshot` of the
`BusView`, which its source fills from another thread. Read-only unless built with a
`CommandSender` (--control)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from rich.table import Table
from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal
from textual.screen import ModalScreen
from textual.widget import Widget
from textual.widgets import Footer, Label, Sparkline

from firmware_py.mechanics.geometry import default_geometry
from firmware_py.mechanics.kinematics import DirectKinematics
from firmware_py.mechanics.rotation import quat_to_rpy
from hil.monitor.sources import CommandSender, ReplaySource, Source
from hil.monitor.view import COLUMNS, N_LEGS, BusView, Snapshot
from protocol.enums import Command

REDRAW_S = 0.08                # 12.5 Hz asked: at least 10 Hz with the redraw's own time
WINDOW_S = 5.0                 # the sparklines' and the export's window
SCROLL_STEP_S = 1.0
SPARK_BARS = 120              # a sparkline's bars at most (each a mean of its samples)
STALE_S = 0.05                 # a leg's frame older than this is shown stale (25 periods)


def _f(x: float, fmt: str, scale: float = 1.0) -> str:
    return "-" if x is None or not math.isfinite(x) else format(x * scale, fmt)


def _bars(data: np.ndarray, n: int = SPARK_BARS) -> list[float]:
    """At most `n` means of consecutive samples: the sparkline shows no more bars than that."""
    if len(data) <= n:
        return data.tolist()
    edges = np.linspace(0, len(data), n + 1).astype(int)
    return (np.add.reduceat(data, edges[:-1]) / np.diff(edges)).tolist()


def _rates_text(rates: dict[str, float]) -> str:
    """Frames per second per message; a numbered family at one rate as N x rate."""
    families: dict[str, list[float]] = {}
    for name, rate in sorted(rates.items()):
        families.setdefault(name.rstrip("0123456789").rstrip("_"), []).append(rate)
    parts = []
    for family, values in families.items():
        if len(values) > 1 and max(values) - min(values) <= 0.05 * max(values):
            parts.append(f"{family} {len(values)}x{np.mean(values):.0f}")
        else:
            parts.append(f"{family} " + "/".join(f"{v:.0f}" for v in values))
    return "  ".join(parts)


def _age_ms(now: float, seen: float) -> str:
    return "-" if not (math.isfinite(now) and math.isfinite(seen)) else f"{(now - seen) * 1e3:.0f}"


class Panel(Widget):
    """Text repainted in place: its size is fixed by the CSS, so a redraw never lays out the
    screen again (a Static's update did, 40 ms a time)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.content: Text | Table = Text()

    def show(self, content: Text | Table) -> None:
        self.content = content
        self.refresh()

    def render(self) -> Text | Table:
        return self.content


class Confirm(ModalScreen[bool]):
    """A yes/no question; y confirms, anything else cancels."""

    BINDINGS = [Binding("y", "answer(True)", "yes"), Binding("n,escape", "answer(False)", "no")]
    DEFAULT_CSS = "Confirm { align: center middle; } Confirm > Label { border: heavy $warning; padding: 1 2; }"

    def __init__(self, question: str):
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        yield Label(f"{self.question}  [y / n]")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


class MonitorApp(App[None]):
    CSS = """
    #top { height: 11; }
    #top > Panel { width: 1fr; border: round $primary; padding: 0 1; }
    #legs { height: 9; border: round $primary; }
    #sparks { grid-size: 3; grid-columns: 8 1fr 1fr; height: 8; border: round $primary; }
    #sparks > Sparkline { height: 1; margin: 0 1; }
    #sparks > Label { height: 1; }
    #bottom { height: 1fr; }
    #bottom > Panel { width: 1fr; border: round $primary; padding: 0 1; }
    #status { height: 1; background: $boost; }
    .absent { display: none; }
    """
    BINDINGS = [Binding("e", "command('ESTOP')", "E-STOP", priority=True),
                Binding("n", "command('ENABLE')", "enable"), Binding("d", "command('DISABLE')", "disable"),
                Binding("r", "reset", "reset"),
                Binding("space", "freeze", "freeze/live"), Binding("left", "scroll(-1)", "back 1 s"),
                Binding("right", "scroll(1)", "forward 1 s"), Binding("x", "export", "export CSV"),
                Binding("q", "quit", "quit")]
    CONTROL_ACTIONS = ("command", "reset")          # only with --control

    def __init__(self, view: BusView, source: Source, title: str, sender: CommandSender | None = None,
                 snapshot: Path | None = None, duration_s: float | None = None, export_dir: Path = Path(".")):
        super().__init__()
        self.view, self.source, self.sender = view, source, sender
        self.title = title
        self.snapshot_path, self.duration_s, self.export_dir = snapshot, duration_s, export_dir
        self.frozen_at: float | None = None          # the window's end while frozen (frames' clock)
        self.redraws = 0
        self.redraw_rate = 0.0
        self.cpu_pct = 0.0
        self.cpu_seconds: list[float] = []          # CPU % of each second frames came in
        self.first_redraw: float | None = None
        self._frames_mark = 0
        self._cpu_mark = (time.monotonic(), time.process_time(), 0)
        self._started = time.monotonic()
        geometry = default_geometry()
        self._dk = DirectKinematics(geometry)
        self._leg_min_m = geometry.leg_min_m
        self.shown: Snapshot | None = None
        self._finishing = False
        self.panels: dict[str, Panel] = {}
        self.sparks: dict[str, Widget] = {}
        self.messages: list[str] = []

    def check_action(self, action: str, parameters: tuple) -> bool | None:
        """Read-only unless --control: the command keys do not exist (nor show) without it."""
        return self.sender is not None or action not in self.CONTROL_ACTIONS

    # -- layout ------------------------------------------------------------------------
    def compose(self) -> ComposeResult:
        with Horizontal(id="top"):
            yield Panel(id="controller")
            yield Panel(id="platform")
            yield Panel(id="host")
        yield Panel(id="legs")
        with Grid(id="sparks"):
            for leg in range(N_LEGS):
                yield Label(f"leg {leg + 1}", id=f"spark-label-{leg}")
                yield Sparkline([], id=f"spark-pos-{leg}", summary_function=np.mean)
                yield Sparkline([], id=f"spark-force-{leg}", summary_function=np.mean)
        with Horizontal(id="bottom"):
            yield Panel(id="bus")
            yield Panel(id="emcy")
        yield Panel(id="status")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#sparks").border_title = f"stroke (left) and force (right), last {WINDOW_S:g} s"
        self.query_one("#legs").border_title = "legs"
        # held from here on: a timer tick during shutdown finds no screen to query
        self.panels = {w.id: w for w in self.query(Panel)}
        self.sparks = {w.id: w for w in self.query("#sparks > *")}
        self.source.start()
        self.set_interval(REDRAW_S, self.redraw)

    def on_unmount(self) -> None:
        self.source.stop()

    # -- drawing -----------------------------------------------------------------------
    def redraw(self) -> None:
        snap = self.view.snapshot() if self.frozen_at is None or self.shown is None else self.shown
        self.shown = snap
        end = snap.now_s if self.frozen_at is None else self.frozen_at
        self._draw(snap, end)
        self._account()
        finished = self.source.done.is_set() or (
            self.duration_s is not None and time.monotonic() - self._started >= self.duration_s)
        if finished and not self._finishing and (self.snapshot_path is not None or self.duration_s is not None):
            self._finishing = True
            snap = self.view.snapshot()          # everything the source fed
            self.shown = snap
            self._draw(snap, snap.now_s if self.frozen_at is None else self.frozen_at)
            self.call_after_refresh(self._finish)   # once the layout shows what was just drawn

    def _finish(self) -> None:
        if self.snapshot_path is not None:
            self.save_screenshot(self.snapshot_path.name, str(self.snapshot_path.parent or Path(".")))
        self.exit()

    def _account(self) -> None:
        self.redraws += 1
        wall, cpu, n = self._cpu_mark
        now = time.monotonic()
        if self.first_redraw is None:
            self.first_redraw = now
        if now - wall >= 1.0:
            self.cpu_pct = 100.0 * (time.process_time() - cpu) / (now - wall)
            self.redraw_rate = (self.redraws - n) / (now - wall)
            self._cpu_mark = (now, time.process_time(), self.redraws)
            frames = self.view.frames
            if frames > self._frames_mark:
                self.cpu_seconds.append(self.cpu_pct)
            self._frames_mark = frames

    def redraw_hz(self) -> float:
        """Redraws per second since the first one."""
        if self.first_redraw is None or self.redraws < 2:
            return 0.0
        return (self.redraws - 1) / max(time.monotonic() - self.first_redraw, 1e-9)

    def _draw(self, s: Snapshot, end_s: float) -> None:
        self.panels["controller"].show(self._controller_text(s))
        self.panels["platform"].show(self._platform_text(s))
        self.panels["host"].show(self._host_text(s))
        self.panels["legs"].show(self._legs_table(s))
        rows = self.view.history(end_s, WINDOW_S) if math.isfinite(end_s) else np.empty((0, 1))
        for leg in range(N_LEGS):
            present = leg < max(s.n_legs, 1)
            for kind in ("label", "pos", "force"):
                widget = self.sparks[f"spark-{kind}-{leg}"]
                if widget.has_class("absent") == present:
                    widget.set_class(not present, "absent")
            if present and len(rows):
                base = 1 + leg * len(COLUMNS)
                for kind, col in (("pos", base), ("force", base + 1)):
                    data = rows[:, col]
                    self.sparks[f"spark-{kind}-{leg}"].data = _bars(data[np.isfinite(data)])
        self.panels["bus"].show(self._bus_text(s))
        self.panels["emcy"].show(self._emcy_text(s))
        self.panels["status"].show(self._status_text(s, end_s))

    def _controller_text(self, s: Snapshot) -> Text:
        t = Text()
        style = "bold red" if s.state in ("FAULT", "ESTOP") else "bold green" if s.state in ("READY", "RUNNING") \
            else "bold yellow"
        t.append("controller  ", "bold")
        t.append(s.state, style)
        t.append(f"   {s.controller}\n")
        t.append("fault       ")
        t.append(s.fault + (f" (leg {s.fault_leg})" if s.fault_leg and s.fault != "NONE" else ""),
                 "bold red" if s.fault not in ("NONE", "-") else "")
        t.append(f"\nwaypoint    {s.active_waypoint}")
        if math.isfinite(s.clock_rate):              # CTRL_CLOCK: the trajectory's clock, slowed online
            t.append(f"   clock {s.clock_rate:.0%}", "bold yellow" if s.clock_rate < 1.0 else "")
        t.append("\n")
        if math.isfinite(s.payload_kg):
            t.append(f"payload     {s.payload_kg:.2f} kg ({'estimated' if s.payload_estimated else 'declared'})\n")
        t.append(f"overruns    {s.overruns}\n")
        t.append(f"compute max {_f(s.compute_max_us, '.0f')} us   "
                 f"period err max {_f(s.period_error_max_us, '.0f')} us\n")
        t.append(f"status age  {_age_ms(s.now_s, s.status_seen_s)} ms\n")
        t.append("  ".join(f"{e.text} ({_age_ms(s.now_s, e.time_s)} ms ago)" for e in s.states[-2:]), "dim")
        return t

    def _platform_text(self, s: Snapshot) -> Text:
        t = Text("platform\n", "bold")
        if s.n_legs == N_LEGS and np.all(np.isfinite(s.positions_m)):
            self._dk.solve(s.positions_m + self._leg_min_m)
            p = self._dk.pose
            rpy = np.degrees(quat_to_rpy(p[3:7]))
            t.append(f"DK   x {p[0] * 1e3:7.1f}  y {p[1] * 1e3:7.1f}  z {p[2] * 1e3:7.1f} mm\n")
            t.append(f"     roll {rpy[0]:6.2f}  pitch {rpy[1]:6.2f}  yaw {rpy[2]:6.2f} deg\n")
        else:
            t.append("DK   - (needs six legs)\n\n")
        if s.attitude_rad is not None:
            r = np.degrees(s.attitude_rad)
            t.append(f"IMU  roll {r[0]:6.2f}  pitch {r[1]:6.2f}  yaw {r[2]:6.2f} deg  {s.imu_status}\n")
        else:
            t.append("IMU  -\n")
        if s.truth_m is not None:
            x, y, z = (v * 1e3 for v in s.truth_m)
            t.append(f"truth x {x:7.1f}  y {y:7.1f}  z {z:7.1f} mm (emulator)\n")
        return t

    def _host_text(self, s: Snapshot) -> Text:
        t = Text("host commands\n", "bold")
        for e in s.host[-4:]:
            t.append(f"{_age_ms(s.now_s, e.time_s):>6} ms ago  {e.text}\n")
        t.append("acks\n", "bold")
        for e in s.acks[-4:]:
            t.append(f"{_age_ms(s.now_s, e.time_s):>6} ms ago  {e.text}\n",
                     "" if "ACCEPTED" in e.text else "yellow")
        return t

    def _legs_table(self, s: Snapshot) -> Table:
        table = Table(expand=True, box=None, header_style="bold")
        for col in ("leg", "pos mm", "vel mm/s", "force N", "pA bar", "pB bar", "m_L kg", "P_L bar", "valve 408",
                    "status", "DHMR", "cmd %", "spool %", "age ms", "E2E rej", "lost"):
            table.add_column(col, justify="right", no_wrap=True)
        for leg in range(max(s.n_legs, 1)):
            g = s.legs[leg]
            age = s.now_s - g.seen_s if math.isfinite(g.seen_s) else math.inf
            stale = age > STALE_S
            table.add_row(
                str(leg + 1), _f(g.position_m, ".2f", 1e3), _f(g.velocity_m_s, ".1f", 1e3), _f(g.force_n, ".1f"),
                _f(g.pa_pa, ".2f", 1e-5), _f(g.pb_pa, ".2f", 1e-5), _f(g.load_mass_kg, ".2f"),
                _f(g.load_pressure_pa, ".2f", 1e-5),
                Text(g.valve_state, "bold red" if "FAULT" in g.valve_state else ""),
                f"{g.status_state} {g.fault_reason}", g.control_bits, _f(g.spool_cmd, ".2f", 1e2),
                _f(g.spool_actual, ".2f", 1e2), Text(_age_ms(s.now_s, g.seen_s), "bold red" if stale else ""),
                str(g.rejected), str(g.lost), style="dim" if stale else "")
        return table

    def _bus_text(self, s: Snapshot) -> Text:
        t = Text("bus\n", "bold")
        total = sum(s.rates.values())
        t.append(f"load {s.load * 100:5.1f} % of 1 Mbit/s   {total:7.0f} frames/s\n")
        t.append(f"SYNC period {_f(s.sync_period_us, '.0f')} us  jitter p99 {_f(s.sync_jitter_p99_us, '.0f')} "
                 f"max {_f(s.sync_jitter_max_us, '.0f')} us\n")
        t.append(_rates_text(s.rates) + "\n")
        t.append("heartbeats ")
        t.append("  ".join(f"{node} {state} ({_age_ms(s.now_s, seen)} ms)"
                           for node, (state, seen) in sorted(s.heartbeats.items())) + "\n")
        for e in s.nmt:
            t.append(f"NMT {e.text} ({_age_ms(s.now_s, e.time_s)} ms ago)\n")
        return t

    def _emcy_text(self, s: Snapshot) -> Text:
        t = Text("EMCY\n", "bold")
        for e in reversed(s.emcy):
            t.append(f"{_age_ms(s.now_s, e.time_s):>7} ms ago  {e.text}\n", "red" if "NO_ERROR" not in e.text else "")
        return t

    def _status_text(self, s: Snapshot, end_s: float) -> Text:
        mode = "LIVE" if self.frozen_at is None else f"FROZEN at {end_s - s.now_s:+.1f} s"
        parts = [mode, f"frames {s.frames}", f"unknown {s.unknown}", f"E2E rejected {s.rejected}",
                 f"lost {s.lost}", f"CPU {self.cpu_pct:.0f} %", f"redraw {self.redraw_rate:.0f} Hz"]
        if isinstance(self.source, ReplaySource):
            parts.append(f"replay {self.source.log_span_s:.1f} s, behind max {self.source.lag_s * 1e3:.0f} ms"
                         + (" (done)" if self.source.done.is_set() else ""))
        if self.source.error:
            parts.append(f"source error: {self.source.error}")
        if self.messages:
            parts.append(self.messages[-1])
        return Text("  |  ".join(parts))

    # -- keys --------------------------------------------------------------------------
    def action_freeze(self) -> None:
        self.frozen_at = None if self.frozen_at is not None else self.view.snapshot().now_s
        self.redraw()

    def action_scroll(self, direction: int) -> None:
        latest = self.view.snapshot().now_s
        if not math.isfinite(latest):
            return
        start = self.frozen_at if self.frozen_at is not None else latest
        self.frozen_at = min(latest, max(self.view.oldest_s(), start + direction * SCROLL_STEP_S))
        self.redraw()

    def action_export(self) -> None:
        s = self.shown or self.view.snapshot()
        end = s.now_s if self.frozen_at is None else self.frozen_at
        path = self.export_dir / f"monitor-{time.strftime('%Y%m%d-%H%M%S')}.csv"
        rows = self.view.export_csv(path, end, WINDOW_S)
        self.messages.append(f"exported {rows} rows to {path}")

    def action_command(self, name: str) -> None:
        if self.sender is not None:
            seq = self.sender.send(Command[name])
            self.messages.append(f"sent {name} (seq {seq})")

    def action_reset(self) -> None:
        if self.sender is not None:
            self.push_screen(Confirm("RESET the controller?"),
                             lambda yes: self.action_command("RESET") if yes else None)
