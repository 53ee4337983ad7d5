"""The one status vocabulary of the static equilibrium: why a load case's Newton stopped.

spec: DESIGN.md "Static equilibrium" (failures are reported per case)."""

import enum


class Status(enum.IntEnum):
    """Why the Newton of a load case stopped: the per-case `StaticSolution.status` codes.

    The one status vocabulary of the statics: every table and message is derived from these
    members. The arrays hold the integer codes (they live inside compiled programs, are vmapped
    and written to files); compare them with the members (`sol.status == Status.CONVERGED`)
    and read a code's meaning with `Status(code).text`.
    """

    NOT_SOLVED = -1, "not solved (the run was interrupted)"  # a results table's case never run
    CONVERGED = 0, "converged"
    MAX_STEPS = 1, "max_steps reached"
    NONFINITE = 2, "non-finite"
    STALLED = 3, "stalled"  # the line search found no descent in the last steps

    def __new__(cls, code: int, text: str):
        member = int.__new__(cls, code)
        member._value_ = code
        member.text = text
        return member


STATUS_TEXT = {int(s): s.text for s in Status}  # code → text (kept for callers of the codes)
