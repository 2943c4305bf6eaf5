"""Fill a case's expectations by running it with real BehaviorTree.CPP (see README.md)."""

import json
import subprocess
import sys
from pathlib import Path

DRIVER = Path(__file__).with_name("driver")


def run(case_path: Path, mode: str) -> dict:
    out = subprocess.run([str(DRIVER), str(case_path), mode], capture_output=True, text=True, timeout=120, check=False)
    lines = [line for line in out.stdout.splitlines() if line.startswith("{")]
    if not lines:
        sys.exit(f"{case_path}: the driver printed no result: {out.stderr[-500:]}")
    return json.loads(lines[-1])


def main() -> None:
    for name in sys.argv[1:]:
        path = Path(name)
        case = json.loads(path.read_text())
        once = run(path, "once")
        if "load_error" in once:
            sys.exit(f"{path}: BT.CPP does not load the tree: {once['load_error']}")
        exactly = run(path, "exactly_once")
        case.update(
            tick_mode="once",
            expected_trace=once["trace"],
            expected_blackboard=once["blackboard"],
            alt_modes={
                "exactly_once": {"expected_trace": exactly["trace"], "expected_blackboard": exactly["blackboard"]}
            },
            btcpp_version="4.8.2",
        )
        path.write_text(json.dumps(case, indent=1))
        print(f"recorded {path}")


if __name__ == "__main__":
    main()
