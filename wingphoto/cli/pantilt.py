"""``wingphoto pantilt``: drive the pan-tilt calibration device through PanTilt.m's schedule."""
from __future__ import annotations

import argparse

_EPILOG = """\
examples:
  wingphoto pantilt --backend dryrun                         # print the schedule's timeline, move nothing
  wingphoto pantilt --backend nidaq --device Dev1 --trigger-line port0/line0
  wingphoto pantilt --backend serial --port /dev/ttyACM0     # Pololu Maestro, channels 0 (pan), 1 (tilt)
  wingphoto pantilt --backend serial --protocol arduino --port COM3 --trigger-channel 7

Start the cameras recording (100 fps in the thesis) before the run, or let the trigger line
start them; then pick the calibration pairs with wingphoto.capture.select_calibration_frames.
The schedule (22 steps: 3 tilts x 7 pans, serpentine, then neutral; 1 s each at 50 Hz PWM) is
wingphoto.pantilt.pan_tilt_schedule; docs/calibration_capture.md explains the device.
"""


def add_parser(sub):
    p = sub.add_parser(
        "pantilt",
        help="drive the pan-tilt calibration board through PanTilt.m's schedule",
        description="Step the calibration board's pan-tilt unit (HS-311 pan servo, S03N tilt servo) "
        "through PanTilt.m's schedule: pan pulse widths linspace(1.3, 1.7, N) ms swept forward, back, "
        "forward, tilt 2.0 / 1.5 / 0.6 ms, each step held --hold seconds, then neutral (1.5, 1.5 ms). "
        "Prints the timeline of commands; --out writes it as CSV.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--backend", choices=["dryrun", "nidaq", "serial"], default="dryrun",
                   help="dryrun (record only, default), nidaq (NI-DAQmx counter PWM, needs the nidaqmx "
                   "package: pip install 'wingphoto[daq]') or serial (servo controller via pyserial)")
    p.add_argument("--port", help="serial port of the servo controller (serial backend), e.g. /dev/ttyACM0 or COM3")
    p.add_argument("--protocol", choices=["maestro", "arduino"], default="maestro",
                   help="serial protocol: Pololu Maestro compact protocol or the sketch in "
                   "extras/pantilt_servo/pantilt_servo.ino (default %(default)s)")
    p.add_argument("--device", default="Dev1", help="NI-DAQmx device (nidaq backend, default %(default)s)")
    p.add_argument("--tilt-counter", default="ctr0", help="counter driving the tilt servo (default %(default)s)")
    p.add_argument("--pan-counter", default="ctr1", help="counter driving the pan servo (default %(default)s)")
    p.add_argument("--trigger-line", default=None,
                   help="NI-DAQmx digital line for the camera trigger, e.g. port0/line0 (raised at the start)")
    p.add_argument("--pan-channel", type=int, default=0, help="Maestro channel of the pan servo (default 0)")
    p.add_argument("--tilt-channel", type=int, default=1, help="Maestro channel of the tilt servo (default 1)")
    p.add_argument("--trigger-channel", type=int, default=None,
                   help="serial backend: Maestro output channel (or, for the Arduino sketch, any value: pin 7) "
                   "for the camera trigger, raised at the start")
    p.add_argument("--tilts", type=int, default=3, help="number of tilt stops (default 3: 2.0, 1.5, 0.6 ms)")
    p.add_argument("--pans", type=int, default=7, help="number of pan stops (default 7: linspace(1.3, 1.7, 7) ms)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds each step is held (default 1)")
    p.add_argument("--no-neutral", action="store_true", help="do not end at neutral (1.5, 1.5 ms)")
    p.add_argument("--realtime", action="store_true",
                   help="with the dry run, really wait --hold seconds per step (hardware backends always do)")
    p.add_argument("--out", default=None, help="write the timeline to this CSV file")
    return p


def run(args):
    from .. import pantilt
    from ..io import atomic_write

    schedule = pantilt.pan_tilt_schedule(args.tilts, args.pans, hold_s=args.hold,
                                         neutral_ms=None if args.no_neutral else (1.5, 1.5))
    if args.backend == "dryrun":
        backend = pantilt.DryRunBackend(trigger=True)
        trigger = True
    elif args.backend == "nidaq":
        backend = pantilt.NIDAQBackend(args.device, tilt_counter=args.tilt_counter, pan_counter=args.pan_counter,
                                       trigger_line=args.trigger_line)
        trigger = args.trigger_line is not None
    else:
        if not args.port:
            raise ValueError("--backend serial needs --port, e.g. --port /dev/ttyACM0 (or COM3)")
        backend = pantilt.SerialBackend(args.port, protocol=args.protocol, pan_channel=args.pan_channel,
                                        tilt_channel=args.tilt_channel, trigger_channel=args.trigger_channel)
        trigger = args.trigger_channel is not None
    n = len(schedule)
    print(f"pan-tilt: {n} steps of {args.hold:g} s ({n * args.hold:g} s) on the {backend.name} backend"
          + (", camera trigger at the start" if trigger else ""))
    timeline = pantilt.run_schedule(schedule, backend, trigger=trigger,
                                    realtime=True if args.realtime else None, progress=backend.realtime)
    cols = ["time_s", "event", "step", "pan_ms", "tilt_ms", "pan_duty", "tilt_duty"]
    print(timeline[cols].to_string(index=False, float_format=lambda v: f"{v:.4f}", na_rep=""))
    if args.out:
        with atomic_write(args.out, "w", encoding="utf-8", newline="") as f:
            timeline.to_csv(f, index=False)
        print(f"wrote {args.out}")
    return 0
