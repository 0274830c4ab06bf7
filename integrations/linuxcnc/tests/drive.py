#!/usr/bin/python3
"""Headless LinuxCNC display for hexacomp's tests: runs the plan in $HEXACOMP_DRIVE_PLAN.

LinuxCNC starts the ini's [DISPLAY]DISPLAY program and shuts down when it exits. This one resets
E-stop, switches the machine on, homes, enables world (teleop) mode, then, as the plan (JSON) says:
  "sampler": {"channel": N, "cfg": TYPES, "out": FILE}
                                           records every sample of the HAL sampler's FIFO N
                                           (full precision, one line of Python reprs each);
  "mdi": [[x, y, z, a, b, c], ...]         moves to each pose by MDI G0 and records the joints
                                           and the motor commands and the component's
                                           uncertainty pin;
  "program": FILE                          runs the G-code program to its end;
  "started": FILE                          is created once the program runs;
  "unhomed": {"ready": FILE, "go": FILE}    before homing: creates "ready" with the machine on
                                           but not homed, and waits for the test to create "go";
  "hold": {"ready": FILE, "done": FILE}     after the moves: creates "ready" (the machine on,
                                           homed, in world mode) and holds LinuxCNC up until the
                                           test creates "done" (for hexacomp-trainer to drive it);
  "without_service": {"seconds": S, "measured": FILE, "restarted": FILE}
                                           after homing, counts the periods the component
                                           faults in S seconds with no service answering,
                                           creates "measured", waits for the test to create
                                           "restarted" and then for the component to connect;
and writes "results" (JSON): homing (the joints at home and the position the forward kinematics
gave for them), the recorded poses and joints, the program's outcome and
every message of LinuxCNC's error channel. Its own failures also end up in the results.
"""
import json
import os
import sys
import threading
import time
import traceback

import hal
import linuxcnc

PLAN = json.load(open(os.environ["HEXACOMP_DRIVE_PLAN"]))
RESULTS = {"homed": False, "mdi": [], "program": None, "errors": [], "failure": None}
stat, command, errors = linuxcnc.stat(), linuxcnc.command(), linuxcnc.error_channel()


def collect_errors():
    while True:
        message = errors.poll()
        if not message:
            return
        RESULTS["errors"].append(message[1])


def wait_until(condition, seconds, what, interval=0.01):
    deadline = time.time() + seconds
    while time.time() < deadline:
        stat.poll()
        collect_errors()
        if condition():
            return
        time.sleep(interval)
    raise TimeoutError(f"{what} within {seconds} s")


def component_state():
    """The hexacomp component's status pins, for failure messages."""
    pins = ["fault", "fault-count", "last-error", "point-status", "model-generation", "blend",
            "uncertainty"]
    return ", ".join(f"{pin} {hal.get_value('hexacomp.0.' + pin)}" for pin in pins)


def joint_outputs():
    return [stat.joint[j]["output"] for j in range(6)]


def steady_joints(seconds, where):
    """The joint outputs once two polls 50 ms apart read exactly the same values."""
    readings = []

    def still():
        readings.append(joint_outputs())
        return len(readings) > 1 and readings[-1] == readings[-2]

    wait_until(still, seconds, f"joints still at {where}", interval=0.05)
    return readings[-1]


def wait_for_file(path, seconds, what):
    deadline = time.time() + seconds
    while not os.path.exists(path):
        if time.time() > deadline:
            raise TimeoutError(f"{what} within {seconds} s")
        time.sleep(0.05)


def prepare_machine():
    command.state(linuxcnc.STATE_ESTOP_RESET)
    command.state(linuxcnc.STATE_ON)
    wait_until(lambda: stat.task_state == linuxcnc.STATE_ON, 10, "machine on")
    if "unhomed" in PLAN:
        open(PLAN["unhomed"]["ready"], "w").close()
        wait_for_file(PLAN["unhomed"]["go"], 300, "the test's go-ahead to home")
    command.home(-1)
    wait_until(lambda: all(stat.homed[j] for j in range(6)), 30, "homing")
    RESULTS["homed"] = True
    command.teleop_enable(1)
    command.wait_complete(5)
    command.mode(linuxcnc.MODE_MDI)
    command.wait_complete(5)
    # Where the forward kinematics put the platform for the joints at home.
    RESULTS["homed_joints"] = steady_joints(10, "home")
    stat.poll()
    RESULTS["homed_position"] = list(stat.position[:6])


def move_to_poses(poses):
    for pose in poses:
        words = " ".join(f"{axis}{value:.10f}" for axis, value in zip("XYZABC", pose))
        command.mdi(f"G0 {words}")
        outcome = command.wait_complete(60)
        if outcome != linuxcnc.RCS_DONE:
            collect_errors()
            raise RuntimeError(f"MDI G0 {words}: wait_complete gave {outcome}; {component_state()}")
        # The commanded position at the pose: the move is over, but for the planner's last steps,
        # which may still be below the 1e-9 tolerance, so the joints are read once they are still.
        def settled():
            at_pose = all(abs(stat.position[k] - pose[k]) < 1e-9 for k in range(6))
            return at_pose and stat.inpos and stat.queue == 0
        wait_until(settled, 10, f"reaching {words}")
        joints = steady_joints(10, words)
        RESULTS["mdi"].append({
            "pose": pose,
            "position": list(stat.position[:6]),
            "joints": joints,
            "motors": [hal.get_value(f"joint.{j}.motor-pos-cmd") for j in range(6)],
            "uncertainty": hal.get_value("hexacomp.0.uncertainty"),
        })


def run_program(path, started_marker):
    command.mode(linuxcnc.MODE_AUTO)
    command.wait_complete(5)
    command.program_open(path)
    command.wait_complete(5)
    began = time.time()
    command.auto(linuxcnc.AUTO_RUN, 0)
    wait_until(lambda: stat.interp_state != linuxcnc.INTERP_IDLE, 10, "program start")
    if started_marker:
        open(started_marker, "w").close()
    wait_until(lambda: stat.interp_state == linuxcnc.INTERP_IDLE, 600, "program end")
    RESULTS["program"] = {
        "seconds": time.time() - began,
        "position": list(stat.position[:6]),
        "task_state_on": stat.task_state == linuxcnc.STATE_ON,
    }


def without_service(settings):
    """The servo thread must run on while no service answers (the component connects from a
    helper thread of its own), and pick up the connection once the service is back."""
    def pin(name):
        return hal.get_value("hexacomp.0." + name)
    began, faulted = time.time(), pin("fault-count")
    time.sleep(settings["seconds"])
    report = RESULTS["without_service"] = {
        "seconds": time.time() - began,
        "faulted": pin("fault-count") - faulted,
        "last_error": pin("last-error"),
    }
    open(settings["measured"], "w").close()
    wait_until(lambda: os.path.exists(settings["restarted"]), 120, "the service restarted")
    began = time.time()
    wait_until(lambda: not pin("fault"), 30, f"the component connected; {component_state()}")
    report["connected_after"] = time.time() - began


class Recorder(threading.Thread):
    """Copies the sampler FIFO to a file until stopped, then drains it."""

    def __init__(self, component, channel, cfg, path):
        super().__init__(daemon=True)
        self.stream = hal.stream(component, hal.sampler_base + channel, cfg)
        self.out = open(path, "w")
        self.stopping = threading.Event()
        self.start()

    def run(self):
        while True:
            sample = self.stream.read()
            if sample is not None:
                self.out.write(" ".join(repr(value) for value in sample) + "\n")
            elif self.stopping.is_set():
                break
            else:
                time.sleep(0.002)
        self.out.close()

    def stop(self):
        self.stopping.set()
        self.join(10)
        RESULTS["sampler_overruns"] = self.stream.num_overruns


def main():
    sampler = None
    try:
        # A HAL component of this process: for the sampler stream and for reading pins.
        component = hal.component("hexacomp-drive")
        if "sampler" in PLAN:
            settings = PLAN["sampler"]
            sampler = Recorder(component, settings["channel"], settings["cfg"], settings["out"])
        component.ready()
        prepare_machine()
        move_to_poses(PLAN.get("mdi", []))
        if "without_service" in PLAN:
            without_service(PLAN["without_service"])
        if "program" in PLAN:
            run_program(PLAN["program"], PLAN.get("started"))
        if "hold" in PLAN:
            open(PLAN["hold"]["ready"], "w").close()
            wait_for_file(PLAN["hold"]["done"], 3600, "the test's end of the session")
        time.sleep(0.2)
        collect_errors()
    except Exception:
        collect_errors()
        RESULTS["failure"] = traceback.format_exc()
    finally:
        if sampler:
            sampler.stop()
        json.dump(RESULTS, open(PLAN["results"], "w"), indent=1)
        command.state(linuxcnc.STATE_OFF)
        # Ends LinuxCNC: its start script waits for the display and then cleans up.
        sys.exit(0)


main()
