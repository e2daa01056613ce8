"""Conformance checking of a rover against docs/protocol.md (``hideseek check-rover``).

Layering (lower modules never import higher ones)::

    peer       the server's end of the link, played by hand; the transcript
    rules      the rule registry and the findings of one check
    link       opening the rover's link with the openers of server.links
    context    what a check's phases share (Checker, Options)
    *_rules    one module per group of rules: its phase and its judge
    runner     check_rover: the phases in order, then the judges
    report     findings as a table or JSON

Built on `server.protocol` (frames, line splitting, catalogue, map codec) and
`server.links`; it shares no state with a running server.
"""

from .context import Options
from .link import LinkUnreachable, RoverLink, parse_rover_link
from .report import as_json, as_table, summary
from .rules import RULES, Finding
from .runner import check_rover

__all__ = ["Options", "LinkUnreachable", "RoverLink", "parse_rover_link",
           "as_json", "as_table", "summary", "RULES", "Finding", "check_rover"]
