"""A target that misbehaves on purpose: the harness's own tests show that hangs and blow-ups are caught."""

from __future__ import annotations

import time
from pathlib import Path

from .harness import Case, Insane, Target


class SelfTestTarget(Target):
    name = "selftest"

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        kinds = ["ok", "error", "crash", "insane", "hang", "ok", "leak", "ok"]
        return [Case(k, k) for k in kinds[:n]]

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.errors import InputError

        if case.data == "error":
            raise InputError("the input is bad; fix it")
        if case.data == "crash":
            raise ValueError("an internal bug")
        if case.data == "insane":
            raise Insane("fps is nan")
        if case.data == "hang":
            time.sleep(3600)
        if case.data == "leak":  # grows by 50 MB every 10 ms, up to 8 GB if nothing stops it
            held = []
            for _ in range(160):
                held.append(bytearray(50 << 20))
                held[-1][::4096] = b"x" * len(held[-1][::4096])  # touch every page: resident, not just reserved
                time.sleep(0.01)


TARGET = SelfTestTarget()
