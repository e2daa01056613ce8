"""Supervisors: OTP-style supervision of actors (domain-free) and, in their own
modules, the supervision trees of the rovers and the whole system.

``spec`` (specs and pure rules), ``state`` (a supervisor's records),
``supervisor`` (the contract and the running supervisor, built on ``children``:
starting and stopping children, and ``restart``: restart decisions) and
``dynamic`` (a supervisor of many children of one spec) depend only on the
``actors`` runtime;
``rover`` builds a rover's tree from the firmware; only the wiring modules
(``system``, ``remote``, the test harness ``harness/`` and the recorder
``recording/``) join ``world`` and ``server`` into a system (tests/test_layers.py).
"""

from .dynamic import DynamicSupervisor, DynamicSupervisorSpec
from .supervisor import (
    AutoShutdown,
    Backoff,
    ChildCounts,
    ChildError,
    ChildInfo,
    ChildSpec,
    ChildStartError,
    ChildType,
    Restart,
    Strategy,
    Supervisor,
    SupervisorSpec,
    TreeNode,
    backoff_delay,
    intensity_exceeded,
)

__all__ = [
    "AutoShutdown", "Backoff", "ChildCounts", "ChildError", "ChildInfo", "ChildSpec",
    "ChildStartError", "ChildType", "DynamicSupervisor", "DynamicSupervisorSpec", "Restart",
    "Strategy", "Supervisor", "SupervisorSpec", "TreeNode", "backoff_delay",
    "intensity_exceeded",
]
