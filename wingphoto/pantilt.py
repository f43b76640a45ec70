"""The pan-tilt device that turns the calibration board: schedule, servo models, backends.

The thesis collected its calibration images with a board on a pan-tilt unit driven by
``PanTilt.m`` (thesis Appendix D): two hobby servos, a Hitec HS-311 (pan) and a Futaba
S03N (tilt), each driven by a counter output of an NI-DAQ card as a 50 Hz PWM train
(period 20 ms; a servo's angle is set by the pulse width, the duty cycle being
``width / 20 ms``). The unit stepped through 3 tilts x 7 pans, holding each stop 1 s,
then went back to neutral, while the two high-speed cameras recorded at 100 fps; the
calibration pairs were then picked from the recordings
(:func:`wingphoto.capture.select_calibration_frames`).

* :func:`pan_tilt_schedule` - the steps (pulse widths, hold times, servo angles) of
  ``PanTilt.m``, configurable;
* :class:`ServoModel`, :data:`HS311`, :data:`S03N` - pulse width <-> shaft angle;
* :func:`run_schedule` - drive a backend through a schedule (optionally raising a
  camera trigger line at the start) and return the timeline;
* backends, one small interface (:class:`PanTiltBackend`): :class:`DryRunBackend`
  (records, needs nothing), :class:`NIDAQBackend` (counter PWM through the ``nidaqmx``
  package, ``pip install wingphoto[daq]``), :class:`SerialBackend` (a Pololu Maestro's
  compact protocol, or the Arduino sketch shipped in
  ``extras/pantilt_servo/pantilt_servo.ino``, through ``pyserial``).

The command line is ``wingphoto pantilt`` (``wingphoto pantilt --help``).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

__all__ = [
    "ServoModel",
    "HS311",
    "S03N",
    "PWM_PERIOD_MS",
    "PAN_DELAY_MS",
    "pan_tilt_schedule",
    "PanTiltBackend",
    "DryRunBackend",
    "NIDAQBackend",
    "SerialBackend",
    "run_schedule",
]

logger = logging.getLogger(__name__)

#: PWM period of both servo channels, ms (50 Hz), as PanTilt.m.
PWM_PERIOD_MS = 20.0
#: The pan channel's pulse train starts this long after the tilt channel's, ms (PanTilt.m).
PAN_DELAY_MS = 16.0


# ============================================================== servo models
@dataclass(frozen=True)
class ServoModel:
    """Pulse width <-> shaft angle of a hobby servo, piecewise linear through three points.

    Attributes
    ----------
    name : str
    min_ms, neutral_ms, max_ms : float
        Pulse widths (ms) that put the shaft at ``min_deg``, 0 and ``max_deg``.
    min_deg, max_deg : float
        Shaft angles (degrees) at ``min_ms`` and ``max_ms`` (default -90 and +90).

    Examples
    --------
    >>> S03N.angle(2.0)
    50.0
    >>> HS311.width(-90.0)
    1.3
    """

    name: str
    min_ms: float
    neutral_ms: float
    max_ms: float
    min_deg: float = -90.0
    max_deg: float = 90.0

    def __post_init__(self):
        if not (0 < self.min_ms < self.neutral_ms < self.max_ms < PWM_PERIOD_MS):
            raise ValueError(
                f"servo {self.name!r}: need 0 < min_ms < neutral_ms < max_ms < {PWM_PERIOD_MS} ms, got "
                f"{self.min_ms}, {self.neutral_ms}, {self.max_ms}"
            )
        if not self.min_deg < 0 < self.max_deg:
            raise ValueError(f"servo {self.name!r}: need min_deg < 0 < max_deg, got {self.min_deg}, {self.max_deg}")

    def angle(self, width_ms):
        """Shaft angle (degrees) for a pulse width (ms); scalars stay scalars."""
        w = np.asarray(width_ms, dtype=np.float64)
        self._check_width(w)
        a = np.interp(w, [self.min_ms, self.neutral_ms, self.max_ms], [self.min_deg, 0.0, self.max_deg])
        return float(np.round(a, 9)) if a.ndim == 0 else np.round(a, 9)

    def width(self, angle_deg):
        """Pulse width (ms) for a shaft angle (degrees); scalars stay scalars."""
        a = np.asarray(angle_deg, dtype=np.float64)
        if np.any(~np.isfinite(a)) or np.any(a < self.min_deg) or np.any(a > self.max_deg):
            raise ValueError(
                f"angle must lie in [{self.min_deg}, {self.max_deg}] degrees for servo {self.name}, got {angle_deg!r}"
            )
        w = np.interp(a, [self.min_deg, 0.0, self.max_deg], [self.min_ms, self.neutral_ms, self.max_ms])
        return float(np.round(w, 12)) if w.ndim == 0 else np.round(w, 12)

    def _check_width(self, w):
        if np.any(~np.isfinite(w)) or np.any(w < self.min_ms - 1e-12) or np.any(w > self.max_ms + 1e-12):
            raise ValueError(
                f"pulse width must lie in [{self.min_ms}, {self.max_ms}] ms for servo {self.name}, got "
                f"{np.asarray(w).tolist()!r}"
            )


#: Hitec HS-311, the pan servo: 1.3 / 1.5 / 1.7 ms = -90 / 0 / +90 degrees.
HS311 = ServoModel("HS-311", 1.3, 1.5, 1.7)
#: Futaba S03N, the tilt servo: 0.6 / 1.5 / 2.4 ms = -90 / 0 / +90 degrees.
S03N = ServoModel("S03N", 0.6, 1.5, 2.4)


# ============================================================== the schedule
#: Most stops per axis: a schedule holds each step for seconds, so more is a typing mistake.
_MAX_STOPS = 1000


def _widths(values, n, default_range, default_three, name):
    if values is not None:
        w = np.asarray(values, dtype=np.float64).ravel()
        if w.size < 1 or not np.all(np.isfinite(w)):
            raise ValueError(f"{name} must be a non-empty sequence of pulse widths in ms, got {values!r}")
        return w
    n = int(n)
    if n < 1:
        raise ValueError(f"the number of {name[:-3]} stops must be >= 1, got {n}")
    if n > _MAX_STOPS:
        raise ValueError(f"the number of {name[:-3]} stops must be at most {_MAX_STOPS}, got {n}")
    if n == 1:
        return np.array([1.5])
    if default_three is not None and n == 3:
        return np.array(default_three, dtype=np.float64)
    return np.linspace(*default_range, n)


def pan_tilt_schedule(
    n_tilts=3, n_pans=7, *, pan_ms=None, tilt_ms=None, neutral_ms=(1.5, 1.5), hold_s=1.0,
    pan_servo=HS311, tilt_servo=S03N, serpentine=True,
):
    """Return the steps of PanTilt.m: pulse widths, hold times and servo angles.

    Parameters
    ----------
    n_tilts, n_pans : int, optional
        Number of tilt and pan stops (PanTilt.m: 3 x 7). Ignored for an axis whose
        widths are given.
    pan_ms : sequence of float, optional
        Pan pulse widths of one sweep, ms. Default ``linspace(1.3, 1.7, n_pans)``
        (PanTilt.m); 1.5 for a single stop.
    tilt_ms : sequence of float, optional
        Tilt pulse width of each row, ms. Default (2.0, 1.5, 0.6) for three tilts
        (PanTilt.m), ``linspace(2.0, 0.6, n_tilts)`` otherwise, 1.5 for a single one.
    neutral_ms : (float, float) or None, optional
        (pan, tilt) widths of the final step (PanTilt.m: 1.5, 1.5 ms); None for no
        final step.
    hold_s : float, optional
        How long each step is held, s (PanTilt.m: 1 s).
    pan_servo, tilt_servo : ServoModel, optional
        Servo models for the angles (default :data:`HS311`, :data:`S03N`).
    serpentine : bool, optional
        Sweep the pan forward, then back, then forward... (PanTilt.m, default); False
        sweeps forward on every row.

    Returns
    -------
    schedule : pandas.DataFrame
        One row per step, in the order the device takes them: ``step`` (from 1, as in
        PanTilt.m), ``pan_ms``, ``tilt_ms`` (pulse widths), ``hold_s``, ``start_s``
        (start of the step from the start of the run), ``pan_duty``, ``tilt_duty``
        (``width / 20 ms``), ``pan_deg``, ``tilt_deg`` (the servo shaft angles: the
        expected board orientation with respect to neutral, degrees), ``tilt_index``,
        ``pan_index`` (the stop's position when the stops are sorted by angle; -1 for
        the neutral step) and ``kind`` (``"pose"`` or ``"neutral"``). ``attrs`` holds
        ``period_ms`` (20) and ``pan_delay_ms`` (16: the pan channel starts 16 ms after
        the tilt channel).

    Raises
    ------
    ValueError
        A width outside its servo's range, a non-positive hold time or count.

    Notes
    -----
    PanTilt.m's 22 steps: pan ``linspace(1.3, 1.7, 7)`` ms, then the same reversed, then
    forward again, then 1.5 (neutral); tilt 2.0 ms for steps 1-7, 1.5 for 8-14, 0.6
    for 15-21, then 1.5; each held 1 s at 50 Hz. The board turns with the servo
    shafts, so ``pan_deg``/``tilt_deg`` are its orientation with respect to the
    neutral pose (where it faces the cameras) for a board mounted directly on the
    shafts; ``wingphoto.synth`` renders the stops as evenly spaced board angles
    (``tilt_index``, ``pan_index``; see :func:`wingphoto.synth.pan_tilt_schedule`).

    Examples
    --------
    >>> s = pan_tilt_schedule()
    >>> len(s), s.pan_ms.iloc[:3].round(4).tolist(), s.tilt_ms.iloc[[0, 7, 14, 21]].tolist()
    (22, [1.3, 1.3667, 1.4333], [2.0, 1.5, 0.6, 1.5])
    >>> float(s.pan_duty.iloc[0]), s.attrs["pan_delay_ms"]
    (0.065, 16.0)
    """
    pans = _widths(pan_ms, n_pans, (1.3, 1.7), None, "pan_ms")
    tilts = _widths(tilt_ms, n_tilts, (2.0, 0.6), (2.0, 1.5, 0.6), "tilt_ms")
    hold = float(hold_s)
    if not np.isfinite(hold) or hold <= 0:
        raise ValueError(f"hold_s must be a positive time in seconds, got {hold_s!r}")
    for servo, name in ((pan_servo, "pan_servo"), (tilt_servo, "tilt_servo")):
        if not isinstance(servo, ServoModel):
            raise ValueError(f"{name} must be a wingphoto.pantilt.ServoModel, got {type(servo).__name__}")
    pan_servo.angle(pans)  # range checks, naming the servo
    tilt_servo.angle(tilts)
    pan_rank = {w: k for k, w in enumerate(sorted(set(np.round(pans, 9))))}
    tilt_rank = {w: k for k, w in enumerate(sorted(set(np.round(tilts, 9))))}
    rows = []
    for r, t in enumerate(tilts):
        sweep = pans[::-1] if (serpentine and r % 2 == 1) else pans
        for p in sweep:
            rows.append((p, t, tilt_rank[round(t, 9)], pan_rank[round(p, 9)], "pose"))
    if neutral_ms is not None:
        try:
            npan, ntilt = (float(v) for v in neutral_ms)
        except (TypeError, ValueError):
            raise ValueError(f"neutral_ms must be (pan, tilt) widths in ms or None, got {neutral_ms!r}") from None
        pan_servo.angle(npan)
        tilt_servo.angle(ntilt)
        rows.append((npan, ntilt, -1, -1, "neutral"))
    df = pd.DataFrame(rows, columns=["pan_ms", "tilt_ms", "tilt_index", "pan_index", "kind"])
    df.insert(0, "step", np.arange(1, len(df) + 1))
    df.insert(3, "hold_s", hold)
    df.insert(4, "start_s", np.arange(len(df)) * hold)
    df.insert(5, "pan_duty", df["pan_ms"] / PWM_PERIOD_MS)
    df.insert(6, "tilt_duty", df["tilt_ms"] / PWM_PERIOD_MS)
    df.insert(7, "pan_deg", pan_servo.angle(df["pan_ms"].to_numpy()))
    df.insert(8, "tilt_deg", tilt_servo.angle(df["tilt_ms"].to_numpy()))
    df.attrs.update(period_ms=PWM_PERIOD_MS, pan_delay_ms=PAN_DELAY_MS,
                    pan_servo=pan_servo.name, tilt_servo=tilt_servo.name)
    return df


def _check_schedule(schedule):
    need = {"step", "pan_ms", "tilt_ms", "hold_s"}
    if not isinstance(schedule, pd.DataFrame) or not need <= set(schedule.columns):
        raise ValueError(
            f"schedule must be a DataFrame with columns {sorted(need)} (see pan_tilt_schedule), got "
            f"{type(schedule).__name__}"
        )
    if len(schedule) == 0:
        raise ValueError("schedule has no steps")
    h = schedule["hold_s"].to_numpy(dtype=float)
    if not np.all(np.isfinite(h) & (h > 0)):
        raise ValueError("schedule: every hold_s must be a positive number of seconds")


# ============================================================== backends
class PanTiltBackend:
    """The small interface every device backend implements.

    ``open()`` starts both PWM channels at the given widths (tilt first, pan
    :data:`PAN_DELAY_MS` later where the hardware can); ``set_widths(pan_ms, tilt_ms)``
    changes the pulse widths; ``set_trigger(level)`` drives the optional camera trigger
    line (TTL high = True); ``close()`` stops the outputs and frees the device.
    ``realtime`` says whether :func:`run_schedule` must really wait for each hold.
    Backends are context managers.
    """

    name = "backend"
    realtime = True
    has_trigger = False

    def open(self, pan_ms, tilt_ms):  # pragma: no cover - interface
        raise NotImplementedError

    def set_widths(self, pan_ms, tilt_ms):  # pragma: no cover - interface
        raise NotImplementedError

    def set_trigger(self, level):
        if level:
            raise ValueError(f"the {self.name} backend has no trigger line configured")

    def close(self):  # pragma: no cover - interface
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


@dataclass
class DryRunBackend(PanTiltBackend):
    """Drive nothing: record every command with its time (the timeline).

    Attributes
    ----------
    events : list of dict
        ``{"event", "pan_ms", "tilt_ms", "trigger"}`` in the order received (the times
        are added by :func:`run_schedule`).
    trigger : bool
        Pretend a trigger line exists (default True).
    """

    trigger: bool = True
    events: list = field(default_factory=list)
    name = "dryrun"
    realtime = False

    @property
    def has_trigger(self):
        return self.trigger

    def open(self, pan_ms, tilt_ms):
        self.events.append({"event": "tilt_pwm_start", "pan_ms": np.nan, "tilt_ms": tilt_ms})
        self.events.append({"event": "pan_pwm_start", "pan_ms": pan_ms, "tilt_ms": np.nan,
                            "delay_s": PAN_DELAY_MS / 1e3})

    def set_widths(self, pan_ms, tilt_ms):
        self.events.append({"event": "set", "pan_ms": pan_ms, "tilt_ms": tilt_ms})

    def set_trigger(self, level):
        if not self.trigger:
            super().set_trigger(level)
        self.events.append({"event": "trigger_high" if level else "trigger_low"})

    def close(self):
        self.events.append({"event": "stop"})


class NIDAQBackend(PanTiltBackend):
    """Counter-output PWM on an NI-DAQ card through ``nidaqmx`` (as PanTilt.m).

    Parameters
    ----------
    device : str, optional
        DAQmx device name (default "Dev1").
    tilt_counter, pan_counter : str, optional
        Counters driving the servos (default "ctr0" tilt, "ctr1" pan), e.g. PFI12/PFI13
        on an X-series card.
    trigger_line : str, optional
        A digital line for the camera trigger, e.g. "port0/line0" (default none).
    nidaqmx : module, optional
        The ``nidaqmx`` module (for tests: a fake); imported when None.

    Notes
    -----
    One task holds both counter channels, continuous pulse trains at 50 Hz with duty
    cycle ``width / 20 ms``; the pan channel's ``initial_delay`` is 16 ms. A new width
    is applied as PanTilt.m did: stop the task, set the duty cycles, start again (the
    servos hold their position through the one missing pulse).
    """

    name = "nidaq"

    def __init__(self, device="Dev1", *, tilt_counter="ctr0", pan_counter="ctr1", trigger_line=None, nidaqmx=None):
        if nidaqmx is None:
            try:
                import nidaqmx  # noqa: F811
            except ImportError:
                raise ValueError(
                    "the nidaq backend needs the nidaqmx package and NI-DAQmx drivers: "
                    "pip install 'wingphoto[daq]' (or use --backend dryrun)"
                ) from None
        self._ni = nidaqmx
        self.device = str(device)
        self.tilt_counter = f"{self.device}/{tilt_counter}"
        self.pan_counter = f"{self.device}/{pan_counter}"
        self.trigger_line = None if trigger_line is None else f"{self.device}/{trigger_line}"
        self._task = self._dio = None
        self._chans = None

    @property
    def has_trigger(self):
        return self.trigger_line is not None

    def open(self, pan_ms, tilt_ms):
        ni = self._ni
        task = ni.Task()
        hz = 1e3 / PWM_PERIOD_MS
        ct = task.co_channels.add_co_pulse_chan_freq(
            self.tilt_counter, freq=hz, duty_cycle=tilt_ms / PWM_PERIOD_MS, initial_delay=0.0)
        cp = task.co_channels.add_co_pulse_chan_freq(
            self.pan_counter, freq=hz, duty_cycle=pan_ms / PWM_PERIOD_MS, initial_delay=PAN_DELAY_MS / 1e3)
        task.timing.cfg_implicit_timing(sample_mode=ni.constants.AcquisitionType.CONTINUOUS)
        self._task, self._chans = task, (cp, ct)
        if self.trigger_line is not None:
            self._dio = ni.Task()
            self._dio.do_channels.add_do_chan(self.trigger_line)
            self._dio.write(False)
        task.start()

    def set_widths(self, pan_ms, tilt_ms):
        cp, ct = self._chans
        self._task.stop()
        cp.co_pulse_duty_cyc = pan_ms / PWM_PERIOD_MS
        ct.co_pulse_duty_cyc = tilt_ms / PWM_PERIOD_MS
        self._task.start()

    def set_trigger(self, level):
        if self._dio is None:
            super().set_trigger(level)
            return
        self._dio.write(bool(level))

    def close(self):
        for t in (self._task, self._dio):
            if t is not None:
                try:
                    t.stop()
                finally:
                    t.close()
        self._task = self._dio = None


class SerialBackend(PanTiltBackend):
    """Hobby-servo controller on a serial port through ``pyserial``.

    Parameters
    ----------
    port : str
        Serial port, e.g. "/dev/ttyACM0" or "COM3".
    protocol : {"maestro", "arduino"}, optional
        ``"maestro"``: a Pololu Maestro's compact protocol (Set Target ``0x84, channel,
        low 7 bits, high 7 bits`` of the width in quarter-microseconds; the trigger is a
        channel configured as an output, high for a target >= 1.5 ms).
        ``"arduino"``: the line protocol of ``extras/pantilt_servo/pantilt_servo.ino``
        (``W <pan_us> <tilt_us>``, ``T 1`` / ``T 0``; each answered ``OK``).
    pan_channel, tilt_channel, trigger_channel : int, optional
        Maestro channels (default 0 pan, 1 tilt, no trigger; the Arduino sketch has
        its pins built in and a trigger on pin 7 when ``trigger_channel`` is not None).
    baudrate : int, optional
        Default 9600 (the Maestro's auto-detected rate, the sketch's rate).
    serial : module, optional
        The ``serial`` module of pyserial (for tests: a fake); imported when None.

    Notes
    -----
    A hobby-servo controller makes the 50 Hz pulse trains itself; the two channels'
    phase (PanTilt.m's 16 ms) is the controller's.
    """

    name = "serial"

    def __init__(self, port, *, protocol="maestro", pan_channel=0, tilt_channel=1, trigger_channel=None,
                 baudrate=9600, timeout=1.0, serial=None):
        if protocol not in ("maestro", "arduino"):
            raise ValueError(f"protocol must be 'maestro' or 'arduino', got {protocol!r}")
        if not port:
            raise ValueError("the serial backend needs a port, e.g. --port /dev/ttyACM0 (or COM3)")
        if serial is None:
            try:
                import serial  # noqa: F811
            except ImportError:
                raise ValueError("the serial backend needs pyserial: pip install 'wingphoto[daq]'") from None
        self._serial_mod = serial
        self.port, self.protocol, self.baudrate, self.timeout = str(port), protocol, int(baudrate), float(timeout)
        self.pan_channel, self.tilt_channel = int(pan_channel), int(tilt_channel)
        self.trigger_channel = None if trigger_channel is None else int(trigger_channel)
        self._port = None

    @property
    def has_trigger(self):
        return self.trigger_channel is not None

    def _maestro_target(self, channel, width_ms):
        q = int(round(width_ms * 4000.0))  # quarter-microseconds
        self._port.write(bytes([0x84, channel, q & 0x7F, (q >> 7) & 0x7F]))

    def _arduino(self, line):
        self._port.write((line + "\n").encode("ascii"))
        reply = self._port.readline().decode("ascii", "replace").strip()
        if reply != "OK":
            raise OSError(f"the pan-tilt Arduino on {self.port} answered {reply!r} to {line!r} (expected 'OK')")

    def open(self, pan_ms, tilt_ms):
        try:
            self._port = self._serial_mod.Serial(self.port, self.baudrate, timeout=self.timeout)
        except Exception as exc:  # serial.SerialException and OS errors
            raise OSError(f"cannot open serial port {self.port}: {exc}") from None
        if self.protocol == "arduino":
            self._arduino("H")  # hello: the sketch answers OK once ready
        self.set_widths(pan_ms, tilt_ms)

    def set_widths(self, pan_ms, tilt_ms):
        if self.protocol == "maestro":
            self._maestro_target(self.tilt_channel, tilt_ms)
            self._maestro_target(self.pan_channel, pan_ms)
        else:
            self._arduino(f"W {int(round(pan_ms * 1000))} {int(round(tilt_ms * 1000))}")

    def set_trigger(self, level):
        if self.trigger_channel is None:
            super().set_trigger(level)
            return
        if self.protocol == "maestro":
            self._maestro_target(self.trigger_channel, 2.0 if level else 1.0)
        else:
            self._arduino(f"T {int(bool(level))}")

    def close(self):
        if self._port is not None:
            try:
                self._port.close()
            finally:
                self._port = None


# ============================================================== running
def run_schedule(schedule, backend, *, trigger=False, realtime=None, sleep=time.sleep, clock=time.monotonic,
                 progress=False):
    """Drive a pan-tilt backend through a schedule and return the timeline.

    Parameters
    ----------
    schedule : pandas.DataFrame
        From :func:`pan_tilt_schedule` (columns ``step, pan_ms, tilt_ms, hold_s``).
    backend : PanTiltBackend
        :class:`DryRunBackend`, :class:`NIDAQBackend`, :class:`SerialBackend` or your own.
    trigger : bool, optional
        Raise the camera trigger line (TTL high) at the start, as the thesis' flapper
        script did, and lower it at the end (default False). The backend must have a
        trigger line.
    realtime : bool, optional
        Really wait ``hold_s`` at each step (default: the backend's ``realtime``; False
        for the dry run, whose times are then the schedule's).
    sleep, clock : callables, optional
        For tests: ``sleep(seconds)`` and a monotonic ``clock()`` in seconds.
    progress : bool, optional
        Show a progress bar over the steps.

    Returns
    -------
    timeline : pandas.DataFrame
        One row per command sent: ``time_s`` (from the start), ``event``
        (``tilt_pwm_start``, ``pan_pwm_start``, ``trigger_high``, ``set``,
        ``trigger_low``, ``stop``), ``step``, ``pan_ms``, ``tilt_ms``, ``pan_duty``,
        ``tilt_duty``. Real backends add no rows of their own; their row times are
        the clock's.

    Raises
    ------
    ValueError
        An invalid schedule, or ``trigger=True`` without a trigger line.
    """
    _check_schedule(schedule)
    if not isinstance(backend, PanTiltBackend):
        raise ValueError(f"backend must be a wingphoto.pantilt.PanTiltBackend, got {type(backend).__name__}")
    if trigger and not backend.has_trigger:
        raise ValueError(f"trigger=True but the {backend.name} backend has no trigger line configured")
    real = backend.realtime if realtime is None else bool(realtime)
    rows = []
    virtual = [0.0]
    t0 = clock() if real else 0.0

    def now():
        return clock() - t0 if real else virtual[0]

    def log(event, step=-1, pan=np.nan, tilt=np.nan, at=None):
        rows.append((now() if at is None else at, event, step, pan, tilt))

    def wait(seconds):
        if real:
            sleep(seconds)
        else:
            virtual[0] += seconds

    steps = schedule.reset_index(drop=True)
    first = steps.iloc[0]
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        def tqdm(x, **_):
            return x
    with backend:
        backend.open(float(first.pan_ms), float(first.tilt_ms))
        log("tilt_pwm_start", int(first.step), np.nan, float(first.tilt_ms))
        log("pan_pwm_start", int(first.step), float(first.pan_ms), np.nan, at=now() + PAN_DELAY_MS / 1e3)
        if trigger:
            backend.set_trigger(True)
            log("trigger_high")
        for k, row in tqdm(steps.iterrows(), total=len(steps), desc="pan-tilt", disable=not progress):
            if k > 0:
                backend.set_widths(float(row.pan_ms), float(row.tilt_ms))
            log("set", int(row.step), float(row.pan_ms), float(row.tilt_ms))
            logger.info("step %d: pan %.4f ms, tilt %.4f ms, hold %.3g s", row.step, row.pan_ms, row.tilt_ms,
                        row.hold_s)
            wait(float(row.hold_s))
        if trigger:
            backend.set_trigger(False)
            log("trigger_low")
        log("stop")
    tl = pd.DataFrame(rows, columns=["time_s", "event", "step", "pan_ms", "tilt_ms"])
    tl = tl.sort_values("time_s", kind="stable").reset_index(drop=True)  # the pan start is 16 ms late
    tl["pan_duty"] = tl["pan_ms"] / PWM_PERIOD_MS
    tl["tilt_duty"] = tl["tilt_ms"] / PWM_PERIOD_MS
    tl.attrs.update(backend=backend.name, realtime=real)
    return tl
