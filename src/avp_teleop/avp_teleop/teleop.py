"""``avp teleop [--driver J]``: drive car J of a running graph from the keyboard (docs/teleop.md).

Keys: up / w faster (forward), down / s slower (reverse below 0), left / a steer left, right / d steer right, space
stop (speed and steering 0), q quit (sends a stop first). The command — ``geometry_msgs/Twist`` (or TwistStamped with
``--stamped``: linear.x the speed, angular.z the yaw rate) — is published on ``/avp/driver<J>/cmd_vel`` at ``--rate``
Hz (10) whether or not a key was pressed, so the simulator's watchdog (``drivers.watchdog``) stops the car only when
this program stops. The line at the bottom shows the command being sent. It joins the running graph's ROS domain as
`avp swap-planner` does.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import sys
import time
from dataclasses import dataclass

#: escape sequences of the arrow keys -> the letter they stand for
ARROWS = {"\x1b[A": "w", "\x1b[B": "s", "\x1b[D": "a", "\x1b[C": "d"}


@dataclass
class TeleopState:
    """Speed [m/s] and yaw rate [rad/s] set by keys; limits as eq. (1)'s (the simulator clamps them anyway)."""

    speed_step: float = 0.5
    yaw_step: float = 0.1
    max_speed: float = 5.0
    max_yaw: float = 1.0
    v: float = 0.0
    omega: float = 0.0
    quit: bool = False

    def key(self, k: str) -> None:
        k = ARROWS.get(k, k).lower()
        if k == "w":
            self.v = min(self.max_speed, self.v + self.speed_step)
        elif k == "s":
            self.v = max(-self.max_speed, self.v - self.speed_step)
        elif k == "a":
            self.omega = min(self.max_yaw, self.omega + self.yaw_step)
        elif k == "d":
            self.omega = max(-self.max_yaw, self.omega - self.yaw_step)
        elif k == " ":
            self.v = self.omega = 0.0
        elif k == "q":
            self.v = self.omega = 0.0
            self.quit = True
        self.v, self.omega = round(self.v, 6), round(self.omega, 6)

    def line(self, topic: str) -> str:
        return (f"{topic}: v {self.v:+.1f} m/s, omega {self.omega:+.2f} rad/s "
                f"({math.degrees(self.omega):+.0f} deg/s)   [arrows/wasd, space stop, q quit]")


def split_keys(buf: str) -> list[str]:
    """Keys of a chunk of terminal input: arrow escape sequences whole, other characters one by one."""
    out, i = [], 0
    while i < len(buf):
        seq = buf[i:i + 3]
        if seq in ARROWS:
            out.append(seq)
            i += 3
        else:
            out.append(buf[i])
            i += 1
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--driver", type=int, default=0, metavar="J", help="the driven car (/avp/driver<J>/cmd_vel) [0]")
    p.add_argument("--stamped", action="store_true", help="publish TwistStamped (the simulator's drivers.stamped)")
    p.add_argument("--rate", type=float, default=10.0, help="messages a second [10]")
    p.add_argument("--speed-step", type=float, default=0.5, help="m/s per key press [0.5]")
    p.add_argument("--yaw-step", type=float, default=0.1, help="rad/s per key press [0.1]")


def run(args: argparse.Namespace) -> int:
    import rclpy
    from geometry_msgs.msg import Twist, TwistStamped

    if args.driver < 0 or not 0 < args.rate <= 100:
        print("[avp teleop] --driver must be >= 0 and --rate in (0, 100]", file=sys.stderr)
        return 2
    state = TeleopState(speed_step=args.speed_step, yaw_step=args.yaw_step)
    topic = f"/avp/driver{args.driver}/cmd_vel"
    rclpy.init()
    node = rclpy.create_node(f"avp_teleop_{args.driver}")
    pub = node.create_publisher(TwistStamped if args.stamped else Twist, topic, 10)

    def send() -> None:
        t = Twist()
        t.linear.x, t.angular.z = state.v, state.omega
        if args.stamped:
            m = TwistStamped(twist=t)
            m.header.stamp = node.get_clock().now().to_msg()
            pub.publish(m)
        else:
            pub.publish(t)

    fd = sys.stdin.fileno()
    restore = _raw(fd)
    period = 1.0 / args.rate
    try:
        next_send = time.monotonic()
        while not state.quit:
            ready, _, _ = select.select([fd], [], [], max(0.0, next_send - time.monotonic()))
            if ready:
                chunk = os.read(fd, 64).decode(errors="ignore")
                if not chunk:  # end of input: stop the car and quit
                    state.key("q")
                for k in split_keys(chunk):
                    state.key(k)
            if time.monotonic() >= next_send or state.quit:
                send()
                next_send += period
                if next_send < time.monotonic():
                    next_send = time.monotonic() + period
                sys.stdout.write("\r" + state.line(topic) + "\x1b[K")
                sys.stdout.flush()
    except KeyboardInterrupt:
        state.key("q")
    finally:
        for _ in range(3):  # the last word is a stop, sent until it has surely left (a reliable writer's data is lost
            send()  # when its process ends first)
            time.sleep(0.05)
        if restore:
            restore()
        sys.stdout.write("\n")
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _raw(fd: int):
    """Put the terminal ``fd`` in cbreak mode (keys without Enter, no echo); returns the restoring function (None
    when ``fd`` is not a terminal)."""
    import termios
    import tty

    if not os.isatty(fd):
        return None
    old = termios.tcgetattr(fd)
    tty.setcbreak(fd)
    return lambda: termios.tcsetattr(fd, termios.TCSADRAIN, old)


def main(argv: list[str] | None = None) -> int:
    """The ``teleop_keyboard`` executable: ``avp teleop`` without the ``avp`` command (it joins ROS_DOMAIN_ID as
    set)."""
    p = argparse.ArgumentParser(prog="teleop_keyboard", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
