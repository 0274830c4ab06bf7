"""hexacomp-trainer's bridge to a running LinuxCNC, through LinuxCNC's own Python interface.

Run by `hexacomp-trainer campaign --machine linuxcnc` (and `verify`, `check`) as
`python3 -c SCRIPT DRIVE_PINS PINS_GIVEN MOVE_TIMEOUT`. It checks that LinuxCNC runs, the machine
is on and every joint homed, no tool length offset is active, switches to world (teleop)
coordinates and MDI, and then answers one JSON request per line on standard input with one JSON
line on standard output:

  {"move": [x, y, z, a, b, c]}   mm and degrees, machine coordinates (work offsets do not
                                  apply): moves there by `G21 G90 G53 G0`, waits until the
                                  motion is done and in position, then until the joints hold
                                  still; answers {"legs": [6 × mm], "drives": [6 × mm],
                                  "position": [x, y, z, a, b, c]} — the joint positions motion
                                  commands, what the drives are commanded (the DRIVE_PINS
                                  pattern with # the joint number, e.g. hexacomp.0.motor-out-#;
                                  joint.#.motor-pos-cmd when there are no such pins: the "ready"
                                  answer names the pins read),
                                  and LinuxCNC's position (mm, degrees). The drives' lengths are
                                  the joints plus (drive pin − joint.#.motor-pos-cmd).

Any failure answers {"error": "..."} (and a failure to start ends the bridge). At the end of
its input, or on SIGTERM (the campaign dying), it restores the units and distance mode it found
(G20, G91) and leaves HAL.
"""
import json
import os
import signal
import sys
import time

try:
    import hal
    import linuxcnc
except ImportError as e:
    print(json.dumps({"error": f"LinuxCNC's Python modules are not installed here ({e})"}),
          flush=True)
    sys.exit(1)

DRIVE_PINS, PINS_GIVEN, MOVE_TIMEOUT = sys.argv[1], sys.argv[2] == "given", float(sys.argv[3])
JOINTS = 6
stat, command, errors = linuxcnc.stat(), linuxcnc.command(), linuxcnc.error_channel()


def answer(message):
    print(json.dumps(message), flush=True)


def messages():
    """LinuxCNC's error channel, drained."""
    found = []
    while True:
        message = errors.poll()
        if not message:
            return found
        found.append(message[1])


def wait_until(condition, seconds, what, interval=0.01):
    deadline = time.time() + seconds
    while time.time() < deadline:
        stat.poll()
        if condition():
            return
        time.sleep(interval)
    raise RuntimeError(f"LinuxCNC did not {what} within {seconds} s")


def drive_pins():
    """The HAL pins of the drives' commands: DRIVE_PINS, or (for the default pattern only) motion's
    motor commands joint.N.motor-pos-cmd when the machine has no such pins."""
    pins = [DRIVE_PINS.replace("#", str(j)) for j in range(JOINTS)]
    try:
        for pin in pins:
            hal.get_value(pin)
        return pins
    except Exception as e:
        if PINS_GIVEN:
            raise RuntimeError(f"the drive pins {pins[0]}… cannot be read ({e}): check "
                               "--linuxcnc-drive-pins")
        return [f"joint.{j}.motor-pos-cmd" for j in range(JOINTS)]


def drive_lengths(joints, pins):
    """The leg lengths the drives are commanded, machine units, joint coordinates: the joints
    plus what lies between motion's motor command and the drive's pin (the hexacomp
    component's correction; motor commands differ from joints by the home offsets)."""
    return [joints[j] + hal.get_value(pins[j]) - hal.get_value(f"joint.{j}.motor-pos-cmd")
            for j in range(JOINTS)]


def start():
    try:
        stat.poll()
    except Exception as e:  # linuxcnc.error, or a SystemError from a half-gone session
        raise RuntimeError(f"LinuxCNC is not running (its status cannot be read: {e}); start "
                           "it with the machine's configuration first")
    if stat.joints < JOINTS:
        raise RuntimeError(f"LinuxCNC has {stat.joints} joints, a hexapod six")
    if any(stat.tool_offset):
        raise RuntimeError("a tool length offset is active: cancel it (G49) so that the "
                           "platform's frame is the one calibrated")
    if stat.task_state != linuxcnc.STATE_ON:
        raise RuntimeError("the machine is in E-stop or switched off: switch it on in LinuxCNC")
    unhomed = [str(j) for j in range(JOINTS) if not stat.homed[j]]
    if unhomed:
        raise RuntimeError(f"the machine is not homed (joints {', '.join(unhomed)}): home it "
                           "in LinuxCNC first")
    if stat.task_mode == linuxcnc.MODE_AUTO and stat.interp_state != linuxcnc.INTERP_IDLE:
        raise RuntimeError("LinuxCNC is running a program: wait until it ends")
    # A campaign killed during a move leaves its MDI command to finish.
    wait_until(lambda: stat.interp_state == linuxcnc.INTERP_IDLE and stat.queue == 0
               and stat.inpos, 120, "finish the move in progress and come to rest")
    command.teleop_enable(1)
    command.wait_complete(5)
    command.mode(linuxcnc.MODE_MDI)
    command.wait_complete(5)
    wait_until(lambda: stat.task_mode == linuxcnc.MODE_MDI, 5, "switch to MDI")
    # HAL pins are read through a component of this process.
    component = hal.component(f"hexacomp-trainer-{os.getpid()}")
    component.ready()
    # The modes to give back: inches (G20) and incremental distances (G91) are changed by the
    # moves' G21 G90.
    modes = " ".join(g for g, code in (("G20", 200), ("G91", 910)) if code in stat.gcodes)
    return modes, stat.linear_units, component, drive_pins()


def move(pose, units_per_mm, pins):
    words = " ".join(f"{axis}{value:.10f}" for axis, value in zip("XYZABC", pose))
    messages()
    command.mdi(f"G21 G90 G53 G0 {words}")
    outcome = command.wait_complete(MOVE_TIMEOUT)
    if outcome != linuxcnc.RCS_DONE:
        said = "; ".join(messages())
        why = f"not within {MOVE_TIMEOUT} s" if outcome == -1 else f"status {outcome}"
        raise RuntimeError(f"MDI G53 G0 {words} did not complete ({why})"
                           f"{': ' + said if said else ''}")
    target = [v * units_per_mm for v in pose[:3]] + list(pose[3:])

    def arrived():
        close = all(abs(stat.position[k] - target[k]) < 1e-7 for k in range(6))
        return close and stat.inpos and stat.queue == 0

    wait_until(arrived, MOVE_TIMEOUT, f"reach {words}")
    # The planner's last steps below the tolerance: read the joints once they hold still.
    readings = []

    def still():
        joints = [stat.joint[j]["output"] for j in range(JOINTS)]
        readings.append((joints, drive_lengths(joints, pins)))
        return len(readings) > 1 and readings[-1] == readings[-2]

    wait_until(still, 10, "hold still", interval=0.05)
    legs, drives = readings[-1]
    return {
        "legs": [v / units_per_mm for v in legs],
        "drives": [v / units_per_mm for v in drives],
        "position": [v / units_per_mm for v in stat.position[:3]] + list(stat.position[3:6]),
    }


def stop(_signal, _frame):
    raise SystemExit(1)


def main():
    signal.signal(signal.SIGTERM, stop)
    try:
        modes, units_per_mm, component, pins = start()
    except Exception as e:
        answer({"error": str(e)})
        return 1
    answer({"ready": True, "units_per_mm": units_per_mm, "drive_pins": pins})
    try:
        for line in sys.stdin:
            if not line.strip():
                continue
            try:
                request = json.loads(line)
                answer(move([float(v) for v in request["move"]], units_per_mm, pins))
            except Exception as e:
                answer({"error": str(e)})
    finally:
        if modes:
            command.mdi(modes)
            command.wait_complete(5)
        component.exit()
    return 0


sys.exit(main())
