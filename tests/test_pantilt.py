"""Pan-tilt device: PanTilt.m's schedule, servo models, backends (dry run and fakes of nidaqmx/pyserial)."""
import numpy as np
import pandas as pd
import pytest

from wingphoto import pantilt
from wingphoto.pantilt import (
    HS311,
    S03N,
    DryRunBackend,
    NIDAQBackend,
    SerialBackend,
    ServoModel,
    pan_tilt_schedule,
    run_schedule,
)


# ------------------------------------------------------------------ schedule = PanTilt.m
def test_schedule_reproduces_pantilt_m_duty_cycles():
    s = pan_tilt_schedule()
    assert len(s) == 22 and s.step.tolist() == list(range(1, 23))
    sweep = np.linspace(1.3, 1.7, 7)
    pan = np.concatenate([sweep, sweep[::-1], sweep, [1.5]])
    tilt = np.array([2.0] * 7 + [1.5] * 7 + [0.6] * 7 + [1.5])
    np.testing.assert_array_equal(s.pan_ms, pan)
    np.testing.assert_array_equal(s.tilt_ms, tilt)
    # PanTilt.m writes duty cycles: width / 20 ms period
    np.testing.assert_allclose(s.pan_duty, pan / 20.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.tilt_duty, tilt / 20.0, rtol=0, atol=1e-15)
    assert s.pan_duty.iloc[0] == pytest.approx(0.065) and s.tilt_duty.iloc[14] == pytest.approx(0.03)
    assert (s.hold_s == 1.0).all() and s.start_s.tolist() == list(np.arange(22.0))
    assert s.attrs["period_ms"] == 20.0 and s.attrs["pan_delay_ms"] == 16.0
    assert s.kind.tolist() == ["pose"] * 21 + ["neutral"]


def test_schedule_angles_follow_the_servo_models():
    s = pan_tilt_schedule()
    np.testing.assert_allclose(s.pan_deg.iloc[:7], [-90, -60, -30, 0, 30, 60, 90], atol=1e-9)
    np.testing.assert_allclose(s.tilt_deg.iloc[[0, 7, 14, 21]], [50, 0, -90, 0], atol=1e-9)
    # every (tilt, pan) stop exactly once among the poses
    poses = s[s.kind == "pose"]
    assert len(set(zip(poses.tilt_index, poses.pan_index))) == 21
    assert poses.tilt_index.iloc[0] == 2 and poses.pan_index.iloc[7] == 6  # serpentine: 8th step pan back at max


def test_schedule_is_configurable():
    s = pan_tilt_schedule(2, 3, hold_s=0.5, neutral_ms=None)
    assert len(s) == 6
    np.testing.assert_allclose(s.pan_ms, [1.3, 1.5, 1.7, 1.7, 1.5, 1.3])
    np.testing.assert_allclose(s.tilt_ms, [2.0] * 3 + [0.6] * 3)
    assert s.start_s.iloc[-1] == 2.5
    s = pan_tilt_schedule(pan_ms=[1.4, 1.6], tilt_ms=[1.5], serpentine=False)
    np.testing.assert_allclose(s.pan_ms, [1.4, 1.6, 1.5])
    assert pan_tilt_schedule(1, 1, neutral_ms=None).pan_ms.tolist() == [1.5]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"pan_ms": [1.2]}, r"pulse width must lie in \[1.3, 1.7\] ms for servo HS-311"),
        ({"tilt_ms": [2.5]}, r"\[0.6, 2.4\] ms for servo S03N"),
        ({"hold_s": 0}, "hold_s must be a positive"),
        ({"n_pans": 0}, "pan stops must be >= 1"),
        ({"neutral_ms": 1.5}, "neutral_ms must be"),
        ({"pan_servo": "HS-311"}, "pan_servo must be"),
    ],
)
def test_schedule_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        pan_tilt_schedule(**kwargs)


def test_servo_models_round_trip_and_refuse_out_of_range():
    assert HS311.angle(1.3) == -90.0 and HS311.angle(1.7) == 90.0 and HS311.angle(1.5) == 0.0
    assert S03N.angle(0.6) == -90.0 and S03N.angle(2.4) == 90.0 and S03N.angle(1.95) == pytest.approx(45.0)
    w = np.linspace(0.6, 2.4, 11)
    np.testing.assert_allclose(S03N.width(S03N.angle(w)), w, atol=1e-12)
    with pytest.raises(ValueError, match="angle must lie in"):
        HS311.width(95)
    with pytest.raises(ValueError, match="min_ms < neutral_ms"):
        ServoModel("bad", 1.5, 1.4, 2.0)


def test_synth_schedule_is_derived_from_the_device_schedule():
    synth = pytest.importorskip("wingphoto.synth")
    cap = synth.pan_tilt_schedule(order="capture")
    dev = pan_tilt_schedule()
    dev = dev[dev.kind == "pose"]
    # same order of stops: board angles are the ranks of the servo angles, evenly spaced
    np.testing.assert_allclose(cap[:, 0], np.linspace(-20, 20, 3)[dev.tilt_index])
    np.testing.assert_allclose(cap[:, 1], np.linspace(-30, 30, 7)[dev.pan_index])
    assert np.all(np.sign(cap[:, 1]) == np.sign(dev.pan_deg))
    raster = synth.pan_tilt_schedule()
    assert sorted(map(tuple, raster)) == sorted(map(tuple, cap))
    assert raster[0].tolist() == [-20.0, -30.0]


# ------------------------------------------------------------------ dry run
def test_dry_run_records_the_timeline_with_trigger():
    s = pan_tilt_schedule()
    be = DryRunBackend()
    tl = run_schedule(s, be, trigger=True)
    sets = tl[tl.event == "set"]
    assert len(sets) == 22
    np.testing.assert_allclose(sets.time_s, s.start_s)
    np.testing.assert_array_equal(sets.pan_ms, s.pan_ms)
    np.testing.assert_allclose(sets.tilt_duty, s.tilt_duty)
    ev = tl.event.tolist()
    assert ev[:4] == ["tilt_pwm_start", "trigger_high", "set", "pan_pwm_start"]
    assert ev[-2:] == ["trigger_low", "stop"]
    assert tl.time_s.iloc[3] - tl.time_s.iloc[0] == pytest.approx(0.016)
    assert tl.time_s.is_monotonic_increasing
    assert tl.time_s.iloc[-1] == pytest.approx(22.0)
    # what the backend itself received: 21 changes after the start, trigger around them
    got = [e["event"] for e in be.events]
    assert got.count("set") == 21 and got[0] == "tilt_pwm_start" and got[-1] == "stop"
    assert got.index("trigger_high") < got.index("set") and got[-2] == "trigger_low"


def test_run_schedule_realtime_uses_the_clock_and_sleep():
    t = [100.0]
    slept = []

    def sleep(dt):
        slept.append(dt)
        t[0] += dt

    s = pan_tilt_schedule(1, 2, hold_s=0.25)
    tl = run_schedule(s, DryRunBackend(trigger=False), realtime=True, sleep=sleep, clock=lambda: t[0])
    assert slept == [0.25, 0.25, 0.25]
    np.testing.assert_allclose(tl[tl.event == "set"].time_s, [0, 0.25, 0.5])


def test_run_schedule_refuses_trigger_without_a_line_and_bad_schedules():
    with pytest.raises(ValueError, match="no trigger line"):
        run_schedule(pan_tilt_schedule(), DryRunBackend(trigger=False), trigger=True)
    with pytest.raises(ValueError, match="schedule must be a DataFrame"):
        run_schedule(pd.DataFrame({"a": [1]}), DryRunBackend())
    with pytest.raises(ValueError, match="backend must be"):
        run_schedule(pan_tilt_schedule(), object())


# ------------------------------------------------------------------ fake nidaqmx
class _FakeChan:
    def __init__(self, log, name, freq, duty_cycle, initial_delay):
        self.log, self.name = log, name
        self.freq, self.initial_delay = freq, initial_delay
        self._duty = duty_cycle
        log.append(("add", name, freq, duty_cycle, initial_delay))

    @property
    def co_pulse_duty_cyc(self):
        return self._duty

    @co_pulse_duty_cyc.setter
    def co_pulse_duty_cyc(self, v):
        self.log.append(("duty", self.name, v))
        self._duty = v


class _FakeTask:
    def __init__(self, log):
        self.log = log
        outer = self

        class CO:
            def add_co_pulse_chan_freq(self, counter, freq, duty_cycle, initial_delay):
                return _FakeChan(log, counter, freq, duty_cycle, initial_delay)

        class DO:
            def add_do_chan(self, line):
                log.append(("do", line))

        class Timing:
            def cfg_implicit_timing(self, sample_mode):
                log.append(("timing", sample_mode))

        self.co_channels, self.do_channels, self.timing = CO(), DO(), Timing()
        self.running = False
        del outer

    def start(self):
        self.running = True
        self.log.append(("start",))

    def stop(self):
        self.running = False
        self.log.append(("stop",))

    def write(self, v):
        self.log.append(("write", v))

    def close(self):
        self.log.append(("close",))


class _FakeNidaqmx:
    class constants:
        class AcquisitionType:
            CONTINUOUS = "continuous"

    def __init__(self):
        self.log = []

    def Task(self):
        return _FakeTask(self.log)


def test_nidaq_backend_drives_two_counters_like_pantilt_m():
    ni = _FakeNidaqmx()
    be = NIDAQBackend("Dev1", trigger_line="port0/line0", nidaqmx=ni)
    s = pan_tilt_schedule()
    run_schedule(s, be, trigger=True, realtime=True, sleep=lambda dt: None)
    adds = [e for e in ni.log if e[0] == "add"]
    assert adds == [("add", "Dev1/ctr0", 50.0, 0.1, 0.0), ("add", "Dev1/ctr1", 50.0, 0.065, 0.016)]
    assert ("timing", "continuous") in ni.log and ("do", "Dev1/port0/line0") in ni.log
    duties = [e for e in ni.log if e[0] == "duty"]
    pan = [d[2] for d in duties if d[1] == "Dev1/ctr1"]
    tilt = [d[2] for d in duties if d[1] == "Dev1/ctr0"]
    np.testing.assert_allclose(pan, s.pan_duty.iloc[1:])
    np.testing.assert_allclose(tilt, s.tilt_duty.iloc[1:])
    writes = [e[1] for e in ni.log if e[0] == "write"]
    assert writes == [False, True, False]  # line low at open, TTL high at the start, low at the end
    assert ni.log[-1] == ("close",) and ni.log.count(("close",)) == 2


def test_nidaq_backend_without_package_says_how_to_install(monkeypatch):
    import builtins

    real = builtins.__import__

    def fake_import(name, *a, **k):
        if name == "nidaqmx":
            raise ImportError("no nidaqmx")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(ValueError, match=r"pip install 'wingphoto\[daq\]'"):
        NIDAQBackend()


# ------------------------------------------------------------------ fake pyserial
class _FakePort:
    def __init__(self, port, baudrate, timeout, replies):
        self.port, self.baudrate, self.timeout = port, baudrate, timeout
        self.written = bytearray()
        self.lines = []
        self.replies = replies
        self.closed = False

    def write(self, data):
        self.written += data
        if data.endswith(b"\n"):
            self.lines.append(data.decode().strip())

    def readline(self):
        return self.replies.pop(0) if self.replies else b"OK\r\n"

    def close(self):
        self.closed = True


class _FakeSerialModule:
    def __init__(self, replies=()):
        self.ports = []
        self.replies = list(replies)

    def Serial(self, port, baudrate, timeout):
        p = _FakePort(port, baudrate, timeout, self.replies)
        self.ports.append(p)
        return p


def test_maestro_compact_protocol_bytes():
    ser = _FakeSerialModule()
    be = SerialBackend("/dev/ttyACM0", pan_channel=0, tilt_channel=1, trigger_channel=5, serial=ser)
    s = pan_tilt_schedule(1, 2, neutral_ms=None, tilt_ms=[2.0])
    run_schedule(s, be, trigger=True)
    b = bytes(ser.ports[0].written)
    cmds = [b[i : i + 4] for i in range(0, len(b), 4)]
    assert all(c[0] == 0x84 for c in cmds)

    def target(c):
        return (c[2] | (c[3] << 7)) / 4.0  # microseconds

    # open: tilt 2000 us on ch 1, pan 1300 us on ch 0; trigger high; next pan; trigger low
    assert [(c[1], target(c)) for c in cmds] == [(1, 2000.0), (0, 1300.0), (5, 2000.0), (1, 2000.0), (0, 1700.0),
                                                 (5, 1000.0)]
    assert ser.ports[0].closed


def test_arduino_line_protocol_and_a_bad_reply():
    ser = _FakeSerialModule()
    be = SerialBackend("COM3", protocol="arduino", trigger_channel=7, serial=ser)
    run_schedule(pan_tilt_schedule(1, 2, neutral_ms=None), be, trigger=True)
    assert ser.ports[0].lines == ["H", "W 1300 1500", "T 1", "W 1700 1500", "T 0"]
    ser = _FakeSerialModule(replies=[b"OK\n", b"ERR range\n"])
    be = SerialBackend("COM3", protocol="arduino", serial=ser)
    with pytest.raises(OSError, match="answered 'ERR range'"):
        run_schedule(pan_tilt_schedule(1, 2), be)
    assert ser.ports[0].closed


def test_serial_backend_bad_arguments():
    with pytest.raises(ValueError, match="protocol must be"):
        SerialBackend("COM3", protocol="ssc32", serial=_FakeSerialModule())
    with pytest.raises(ValueError, match="needs a port"):
        SerialBackend("", serial=_FakeSerialModule())


def test_module_constants():
    assert pantilt.PWM_PERIOD_MS == 20.0 and pantilt.PAN_DELAY_MS == 16.0


# ------------------------------------------------------------------ through the CLI
def test_cli_dryrun_prints_and_writes_the_timeline(tmp_path, capsys):
    from wingphoto.cli import main

    out = tmp_path / "timeline.csv"
    assert main(["pantilt", "--backend", "dryrun", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "22 steps of 1 s (22 s) on the dryrun backend, camera trigger at the start" in text
    tl = pd.read_csv(out)
    sets = tl[tl.event == "set"]
    np.testing.assert_allclose(sets.pan_duty, pan_tilt_schedule().pan_duty)
    assert tl.event.iloc[1] == "trigger_high"


def test_cli_nidaq_and_serial_with_fake_hardware(monkeypatch, capsys):
    import sys

    from wingphoto.cli import main

    ni = _FakeNidaqmx()
    monkeypatch.setitem(sys.modules, "nidaqmx", ni)
    monkeypatch.setattr(pantilt.time, "sleep", lambda dt: None)
    assert main(["pantilt", "--backend", "nidaq", "--device", "Dev2", "--trigger-line", "port0/line1",
                 "--tilts", "1", "--pans", "2", "--hold", "0.01"]) == 0
    assert ("add", "Dev2/ctr1", 50.0, 0.065, 0.016) in ni.log and ("do", "Dev2/port0/line1") in ni.log
    ser = _FakeSerialModule()
    monkeypatch.setitem(sys.modules, "serial", ser)
    assert main(["pantilt", "--backend", "serial", "--port", "/dev/ttyFAKE", "--protocol", "arduino",
                 "--tilts", "1", "--pans", "2", "--hold", "0.01", "--no-neutral"]) == 0
    assert ser.ports[0].port == "/dev/ttyFAKE" and ser.ports[0].lines == ["H", "W 1300 1500", "W 1700 1500"]
    capsys.readouterr()
    assert main(["pantilt", "--backend", "serial"]) == 1
    assert "--backend serial needs --port" in capsys.readouterr().err
