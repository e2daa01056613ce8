"""The console's widgets, one per module; each is fed from `tui.snapshot.Snapshot`."""

from tui.widgets.fault_dialog import FaultDialog, FaultRequest
from tui.widgets.game_panel import GamePanel
from tui.widgets.help_screen import HelpScreen
from tui.widgets.map_view import MapView
from tui.widgets.message_log import MessageLog
from tui.widgets.queue_table import QueueTable
from tui.widgets.supervision_tree import SupervisionTree
from tui.widgets.timeline import Timeline

__all__ = ["FaultDialog", "FaultRequest", "GamePanel", "HelpScreen", "MapView", "MessageLog",
           "QueueTable", "SupervisionTree", "Timeline"]
