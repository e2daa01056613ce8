"""Every number of the firmware, counted and classified; writes docs/tunables.md.

Every numeric constant of ``actors/firmware`` (module level, class level and
the fields of option classes; enum members are names, not numbers, and are
left out) is one of:

* **derived**: computed from other quantities (the hardware spec, a noise
  model, another constant), not typed;
* **physical**: a documented quantity with a unit (a range, a speed, a noise
  level, a time the hardware or a protocol takes);
* **structural**: an iteration bound, a buffer or lattice size, a record's
  initial value, a code of the wire, a table value of a distribution;
* **policy**: a threshold or count of a hand-tuned rule.

``python -m benchmarks.tunables`` rewrites ``docs/tunables.md`` from the code;
``--check`` exits 1 when the file and the code disagree (``tests/test_numbers.py``
does the same, and checks that every number is classified).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import enum
import importlib
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["KINDS", "Number", "classify", "numbers", "render", "main"]

ROOT = Path(__file__).resolve().parent.parent
FIRMWARE = ROOT / "actors" / "firmware"
DOC = ROOT / "docs" / "tunables.md"
KIND_NAMES = ("derived", "physical", "structural", "policy")

# ``module[.Class]`` (below ``actors.firmware``) -> {name: kind}; a number computed in
# the code is derived whatever is written here, so only typed numbers are listed.
KINDS: dict[str, dict[str, str]] = {
    "drivers.ir": {"ADC_RAILS": "physical", "MAX_LEASE_S": "structural"},
    "drivers.lidar": {"MIN_SAMPLES": "structural",
                      "MIN_TRIPLES": "structural", "GARBLED_SHARE": "policy",
                      "GARBLED_MIN": "structural", "FAULT_BATCHES": "policy",
                      "RECOVER_BATCHES": "policy"},
    "drivers.lidar.HealthOptions": {"noise_limit_cm": "physical"},
    "drivers.motor.MotorTuning": {
        "period_s": "physical", "cruise_fraction": "physical", "decel_cm_s2": "physical",
        "gain_per_s": "physical", "min_speed_cm_s": "physical", "coupling_per_s": "physical",
        "blocked_after_s": "physical", "blocked_cm": "physical", "settle_s": "physical",
        "motor_tau_s": "physical"},
    "drivers.tread_monitor": {
        "MODEL_SIGMA": "physical", "FAULT_Z": "policy", "BOTH_MOVE_RATIO": "policy",
        "SILENT_OTHER": "policy", "PUSH_RATIO": "policy", "PUSH_WINDOW_CM": "policy",
        "_NO_CARRY": "structural"},
    "drivers.wifly": {"_GRID_TOLERANCE": "structural", "_MAX_STEPS": "structural"},
    "hardware": {"LIDAR_SYNC": "structural", "LIDAR_PACKET_SIZE": "structural",
                 "LIDAR_SAMPLES_PER_REV": "physical",
                 "TREAD_LEFT": "structural", "TREAD_RIGHT": "structural"},
    "hardware.HardwareSpec": {"length_cm": "physical", "width_cm": "physical",
                              "max_speed_cm_s": "physical"},
    "localisation.belief": {"RESAMPLE_ESS": "structural", "MIN_CLUSTER_WEIGHT": "policy",
                            "MAX_CLUSTERS": "structural"},
    "localisation.belief.BeliefOptions": {"particles": "structural"},
    "localisation.capped_edt": {"_MAX_CELLS": "structural"},
    "localisation.clusters": {
        "CELL_CM": "structural", "CELL_DEG": "structural", "SMOOTH_CELLS": "structural",
        "PEAK_FLOOR": "policy", "VALLEY": "policy", "MAX_PEAKS": "structural",
        "MAX_LATTICE_CELLS": "structural",
        "_LINE_SAMPLES": "structural", "_TINY": "structural"},
    "localisation.contact_model.ContactOptions": {"sigma_cm": "physical",
                                                  "unmapped_weight": "physical"},
    "localisation.dead_reckoning": {"MAX_PENDING": "structural"},
    "localisation.face_information": {"MIN_NORMAL": "policy"},
    "localisation.free_space_model.FreeSpaceOptions": {"inside_likelihood": "physical"},
    "localisation.gaussian_pose": {"CHI2_2D_95": "structural", "Z_95": "structural"},
    "localisation.motion_model.MotionNoise": {"encoder_sigma": "physical",
                                              "turn_sigma": "physical"},
    "localisation.odometry_fault.OdometryFaultNoise": {"unseen_fault_per_s": "physical"},
    "localisation.odometry_fault.FitEvidence": {"d2_match": "structural",
                                                "d2_match_wide": "structural",
                                                "d2_match_alt": "structural"},
    "localisation.scan_likelihood": {
        "MAX_BEAMS": "structural", "UNKNOWN_HIT": "structural",
        "GATE_CHI2": "structural", "FLOOR_CM": "physical",
        "FLOOR_DEG": "physical"},
    "localisation.scan_likelihood.ScanOptions": {
        "sigma_hit_cm": "physical", "z_rand": "physical", "new_ground_cm": "physical",
        "independent_hits": "physical"},
    "localisation.scan_likelihood.ScanFit": {"log_fit": "structural"},
    "mapping.map_management": {"_CORRECTION_WAIT_S": "structural",
                               "_SEARCH_EVERY_S": "structural", "UPDATE_MIN_CM": "policy",
                               "UPDATE_MIN_DEG": "policy", "_END_BATCHES": "policy"},
    "mapping.scan_match": {
        "ITERATIONS": "structural", "BLUR_WIDE": "structural", "BLUR_NARROW": "structural",
        "DAMPING": "structural",
        "RELOCALISE_TURN_DEG": "structural", "RELOCALISE_STEP_DEG": "structural",
        "RELOCALISE_MARGIN": "policy"},
    "mapping.scan_match.MatchOptions": {"max_shift_cm": "physical", "max_turn_deg": "physical",
                                        "prior_per_point": "physical"},
    "mapping.scan_window": {"WINDOW_SWEEP_DEG": "physical", "WINDOW_TURN_DEG": "structural",
                            "_STILL_CM": "structural", "WINDOW_TRAVEL_CM": "policy"},
    "mapping.sensor_model.LogOddsModel": {
        "l_free": "physical", "l_occ": "physical", "l_min": "physical", "l_max": "physical",
        "free_threshold": "physical", "occ_threshold": "physical",
        "max_range_cm": "physical", "ray_step": "structural",
        "grazing_margin_cells": "physical"},
    "nav.base": {"POSE_REPORT_TICKS": "structural", "SEND_TIMEOUT_S": "structural",
                 "OUTBOX": "structural"},
    "nav.controller": {"MOTION_TIMEOUT_S": "structural", "POSE_WAIT_S": "structural",
                       "TURN_RATE_DEG_S": "physical"},
    "nav.exploration": {
        "MIN_FACE_CELLS": "policy", "MAX_INCIDENCE_DEG": "physical", "RECHOOSE_STEPS": "policy",
        "OBSTACLE_TURNS": "policy", "MAX_CHOICES": "structural",
        "KEEP_SHARE": "policy", "BLACKLIST": "structural", "SIGHTINGS": "policy",
        "UNSEEABLE": "structural",
        "FUTILE_TRIPS": "policy", "MIN_GAIN_CELLS": "policy", "MIN_GAIN_SHARE": "policy"},
    "nav.exploration.ExplorationState": {"steps": "structural", "budget": "structural",
                                         "blocks": "structural",
                                         "turned_away": "structural"},
    "nav.hider": {"_SHIFT_STEP_CM": "structural", "_SHIFT_BEARINGS": "structural",
                  "_SHIFT_TRIES": "structural"},
    "nav.homing": {"HOME_BLOCKS": "structural"},
    "nav.localiser": {"START_SIGMA_CM": "physical", "START_SIGMA_DEG": "physical",
                      "RETRY_PRIOR_SHARE": "policy"},
    "nav.mapper": {"FIRST_SCANS": "structural",
                   "CHANGE_CELLS": "policy", "CHANGE_SHARE": "policy", "PROBE_S": "structural",
                   "UPLOAD_WAIT_S": "structural"},
    "nav.mapping_options.MappingOptions": {
        "lidar_duty": "physical", "view_range_cm": "physical", "reach_cm": "physical",
        "stop_cm": "physical", "stable_window_s": "physical", "budget_s": "physical",
        "home_budget_s": "physical", "home_reach_cm": "physical",
        "lidar_pause_s": "physical"},
    "nav.nudge": {"NUDGE_STEP_MAX_CM": "policy", "MAX_NUDGES": "structural",
                  "NUDGE_REACH_CM": "policy", "PROBE_WIDTH_CM": "policy"},
    "nav.place": {"SAME_PLACE_CM": "policy"},
    "nav.options.NavOptions": {
        "tick_s": "physical", "step_cm": "physical", "waypoint_tol_cm": "physical",
        "goal_tol_cm": "physical", "align_tol_deg": "physical", "heading_tol_deg": "physical",
        "speed_cm_s": "physical", "plan_margin_cm": "physical", "spot_margin_cm": "physical",
        "hide_within_cm": "physical", "narrow_margin_cm": "physical", "backoff_cm": "physical",
        "nudge_step_cm": "physical", "tread_hold_s": "physical", "settle_s": "physical"},
    "nav.passage_approach": {"AXIS_SWEEP_DEG": "structural"},
    "nav.recovery": {"REPLAN_LIMIT": "structural", "STALL_HOLDS": "structural"},
    "nav.route": {"MAX_CORRECTIONS": "structural"},
    "nav.route_nav": {"MAP_RETRY_S": "structural"},
    "nav.search": {"RING_POINTS": "structural", "RING_MAX_CM": "structural",
                   "WIDE_MAX_RINGS": "structural", "WIDE_MAX_POINTS": "structural",
                   "SEARCH_SCAN_DEG": "physical", "SEARCH_IR_WAIT_S": "physical",
                   "SWEEP_TURN_DEG": "structural",
                   "SWEEP_MAX_STEPS": "structural"},
    "nav.seeker": {"IR_LEASE_TICKS": "structural", "STANDOFF_RING_STEP_DEG": "structural",
                   "MAX_STANDOFF_PLANS": "structural", "IR_PINNED_WAIT_S": "policy"},
    "nav.seeker.SeekingOptions": {
        "standoffs_cm": "physical", "settle_s": "physical", "ir_wait_s": "physical",
        "close_cm": "physical", "ir_half_fov_deg": "physical", "range_cm": "physical",
        "sweep_step_cm": "physical", "wide_search_s": "physical"},
    "nav.sensor_watch": {"LIDAR_SILENT_S": "policy", "ODO_HOLD_S": "policy",
                         "SHORT_HOLD_S": "policy", "CONTACT_CELLS": "policy"},
    "nav.tread_faults": {"TREAD_HOLDS": "structural", "TREAD_CONTACT_S": "policy",
                         "TREAD_STOP_S": "structural"},
    "origin_wire": {"_INT16": "structural", "MM": "structural", "CM": "structural"},
    "payloads.Field": {"scale": "structural"},
    "telemetry": {"_POLL_S": "structural", "_MAP_FRAMES_PER_ROUND": "structural",
                  "_CELLS_PER_FRAME": "structural"},
    "planning.frontier.Frontier": {"open_share": "structural"},
    "planning.viewpoint": {
        "RAYS": "structural", "REVEAL_DEPTH_CELLS": "structural", "FACE_SAMPLES": "structural",
        "LATTICE_SAMPLES": "structural", "TRAVEL_FLOOR_CM": "policy",
        "_BACKOFF_CELLS": "structural", "_SNAP_CELLS": "structural",
        "_VIEW_TURNS_DEG": "structural"},
    "planning.viewpoint.Viewpoint": {"face_cells": "structural"},
    "scan_hits": {"MIN_POINTS": "structural", "MIN_JUDGED": "policy",
                  "MIN_RANGE_CM": "physical", "MAX_RANGE_CM": "physical"},
}


@dataclass(frozen=True, slots=True)
class Number:
    """One numeric constant of the firmware."""

    owner: str
    """``module`` or ``module.Class``, below ``actors.firmware``."""
    name: str
    value: Any
    computed: bool
    """Its value is an expression of other quantities, not a typed literal."""
    doc: str
    """The first sentence of its docstring or trailing comment ("" when none)."""


def _is_number(value: Any) -> bool:
    if isinstance(value, bool | enum.Enum):  # an enum member is a name, not a number
        return False
    if isinstance(value, int | float):
        return True
    return isinstance(value, tuple) and bool(value) and all(_is_number(v) for v in value)


def _is_literal(node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return True
    if isinstance(node, ast.UnaryOp) and isinstance(node.operand, ast.Constant):
        return True
    return isinstance(node, ast.Tuple) and all(_is_literal(e) for e in node.elts)


def _doc(body: list[ast.stmt], i: int, lines: list[str]) -> str:
    """The docstring after statement ``i`` of ``body``, else its trailing comment."""
    nxt = body[i + 1] if i + 1 < len(body) else None
    if isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and \
            isinstance(nxt.value.value, str):
        text = " ".join(nxt.value.value.split())
    else:
        line = lines[body[i].lineno - 1]
        text = line.split("#", 1)[1].strip() if "#" in line else ""
    end = text.find(". ")
    return text if end < 0 else text[:end + 1]


def _assigned(body: list[ast.stmt]) -> list[tuple[int, str, ast.expr]]:
    out = []
    for i, stmt in enumerate(body):
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and \
                isinstance(stmt.targets[0], ast.Name):
            out.append((i, stmt.targets[0].id, stmt.value))
        elif isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and \
                stmt.value is not None:
            out.append((i, stmt.target.id, stmt.value))
    return out


def _default(cls: type, name: str) -> Any:
    if dataclasses.is_dataclass(cls):
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if name in fields:
            return fields[name].default
    return getattr(cls, name, None)


def numbers() -> list[Number]:
    """Every numeric constant of ``actors/firmware``, in source order."""
    out: list[Number] = []
    for path in sorted(FIRMWARE.rglob("*.py")):
        rel = path.relative_to(FIRMWARE).with_suffix("")
        owner = ".".join(rel.parts).removesuffix(".__init__").removesuffix("__init__")
        module = importlib.import_module(f"actors.firmware.{owner}".rstrip("."))
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        tree = ast.parse(text)
        for i, name, value in _assigned(tree.body):
            v = getattr(module, name, None)
            if _is_number(v):
                out.append(Number(owner, name, v, not _is_literal(value),
                                  _doc(tree.body, i, lines)))
        for node in tree.body:
            cls = getattr(module, node.name, None) if isinstance(node, ast.ClassDef) else None
            if not isinstance(cls, type) or issubclass(cls, enum.Enum):
                continue
            for i, name, value in _assigned(node.body):
                v = _default(cls, name)
                if _is_number(v):
                    out.append(Number(f"{owner}.{node.name}", name, v,
                                      not _is_literal(value), _doc(node.body, i, lines)))
    return out


def classify(n: Number) -> str | None:
    """The kind of ``n`` (None: not classified in `KINDS`)."""
    if n.computed:
        return "derived"
    return KINDS.get(n.owner, {}).get(n.name)


def _value(v: Any) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_value(x) for x in v) + ")"
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def render(found: list[Number] | None = None) -> str:
    """docs/tunables.md for the numbers ``found`` (default: the firmware's now)."""
    found = numbers() if found is None else found
    kinds = [classify(n) for n in found]
    counts = {k: kinds.count(k) for k in KIND_NAMES}
    out = ["# Every number of the firmware", "",
           "Generated by `python -m benchmarks.tunables` from the code of `actors/firmware`;",
           "`tests/test_numbers.py` fails when this page and the code disagree. Each",
           "module-level, class-level and option-field number is classified (the kinds:",
           "`benchmarks/tunables.py`): derived (computed from other quantities), physical",
           "(a documented quantity with a unit), structural (a bound, a size, a code, a",
           "record's initial value, a table value), policy (a threshold of a hand-tuned",
           "rule). Why each number is what it is: its docstring in the code.", "",
           "| kind | numbers |", "|---|---|"]
    out += [f"| {k} | {counts[k]} |" for k in KIND_NAMES]
    out += ["", "| kind | where | name | value | what |", "|---|---|---|---|---|"]
    for kind in KIND_NAMES:
        for n, k in zip(found, kinds, strict=True):
            if k == kind:
                doc = n.doc.replace("|", "/")
                out.append(f"| {k} | `{n.owner}` | `{n.name}` | {_value(n.value)} | {doc} |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write docs/tunables.md (or, with ``--check``, say whether it is current)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.tunables",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when docs/tunables.md differs from the code")
    args = parser.parse_args(argv)
    found = numbers()
    missing = [f"{n.owner}.{n.name}" for n in found if classify(n) is None]
    if missing:
        print(f"unclassified numbers: {', '.join(missing)}", file=sys.stderr)
        return 1
    text = render(found)
    if args.check:
        current = DOC.read_text(encoding="utf-8") if DOC.exists() else ""
        if current != text:
            print("docs/tunables.md differs from the code: run python -m benchmarks.tunables",
                  file=sys.stderr)
            return 1
        return 0
    DOC.write_text(text, encoding="utf-8")
    kinds = [classify(n) for n in found]
    print(", ".join(f"{k} {kinds.count(k)}" for k in KIND_NAMES))
    return 0


if __name__ == "__main__":
    sys.exit(main())
