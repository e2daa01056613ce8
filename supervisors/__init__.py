"""Supervisors: OTP-style supervision of actors (domain-free) and, in their own
modules, the supervision trees of the rovers and the whole system.

``supervisor`` depends only on the ``actors`` runtime; ``rover`` builds a
rover's tree from the firmware; only the wiring modules (``system``,
``remote``, the test harness ``harness/`` and the recorder ``recording/``)
join ``world`` and ``server`` into a system (tests/test_layers.py).
"""

from .supervisor import (
    Backoff,
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
    "Backoff", "ChildInfo", "ChildSpec", "ChildStartError", "ChildType", "Restart", "Strategy",
    "Supervisor", "SupervisorSpec", "TreeNode", "backoff_delay", "intensity_exceeded",
]
