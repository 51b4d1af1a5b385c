"""Exception types a caller can catch.

Every error that a user can cause (a bad file, a target the arm cannot reach, an invalid action) is
an :class:`AftirError`, so a CLI prints its one-line message and exits with status 2 instead of a
traceback. Each also derives from the built-in type a caller would expect (``ValueError``...).
"""

from __future__ import annotations


class AftirError(Exception):
    """Base class of every user-facing error of aftir_rl."""


class ConfigError(AftirError, ValueError):
    """A YAML configuration (tank, agent) is malformed: unknown key, bad value, missing file.

    ``param``: the parameter of the call whose value the message is about, if one is (a
    command line puts the name of the flag that gave it before the message).
    """

    def __init__(self, message: str = "", param: str | None = None) -> None:
        super().__init__(message)
        self.param = param


class UnexpectedArgumentError(ConfigError, TypeError):
    """A keyword argument a constructor does not take.

    Also a ``TypeError``, as Python's own for an unexpected keyword argument, and worded like it:
    wrappers that try an argument and drop it on that error (TorchRL's ``GymEnv`` passes
    ``frameskip`` to every env) go on without it.
    """


class TargetError(AftirError, ValueError):
    """A target is outside the tank, inside an obstacle, or unreachable from the start."""


class CheckpointError(AftirError, ValueError):
    """A saved model (Q-table ``.npz``) cannot be read or does not fit the environment."""


class InvalidActionError(AftirError, ValueError):
    """An action outside the environment's action space was passed to ``step``."""


class PlanningError(AftirError, ValueError):
    """A planner found no valid posture; the message starts "Cannot reach the target: "."""


class PlanningTimeout(PlanningError):
    """A planner ran past its wall-clock guard before its work budget was spent.

    Not a verdict on the target: the same call on an idler machine may find a route. The
    message starts "Planning timed out: ".
    """


class PhysicsError(AftirError, ValueError):
    """The physics check could not simulate a motion (its rod left every finite bound)."""


class MissingExtraError(AftirError, ImportError):
    """An optional dependency is not installed; the message names the extra that brings it."""
