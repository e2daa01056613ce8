"""``hideseek report CAMPAIGN.sqlite --html FILE``: a campaign's results as one page.

The page (`tui.pictures.campaign_page`) holds charts of the found rate by fault
kind and by room and of the time to find, and each failure with the command that
plays it again and its shrunk schedule when the campaign shrank it. The store is
opened read-only. Exit status: 0, or 2 bad input (no such store or campaign, a
page that cannot be written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("store", metavar="CAMPAIGN.sqlite",
                        help="a campaign store (hideseek campaign --out)")
    parser.add_argument("--html", required=True, metavar="FILE",
                        help="where to write the page (one self-contained HTML file)")
    parser.add_argument("--campaign", type=int, default=None, metavar="ID",
                        help="which campaign of the store (default: the newest)")


def run(args: argparse.Namespace) -> int:
    from supervisors.harness.campaign.refs import CampaignError
    from supervisors.harness.campaign.store import read_campaign
    from tui.pictures.campaign_page import campaign_html

    try:
        if not Path(args.store).is_file():
            raise CampaignError(f"no campaign store {args.store}")
        cid, summary, games = read_campaign(args.store, args.campaign)
        page = campaign_html(cid, summary, games, source=Path(args.store).name)
        Path(args.html).write_text(page, encoding="utf-8")
    except CampaignError as exc:
        print(f"hideseek report: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"hideseek report: cannot write {args.html}: {exc.strerror or exc}",
              file=sys.stderr)
        return 2
    failed = sum(g["outcome"] != "found" or bool(g["violations"]) for g in games)
    print(f"{args.html}: campaign {cid}, {len(games)} games, {failed} failures")
    return 0
