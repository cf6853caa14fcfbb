"""`hydrapod campaign run SPEC.toml`: a sweep or Monte-Carlo of whole HIL runs on Dask."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from program.cliutil import number_in_range, output_dir
from program.errors import UserInputError

SCHEDULER = re.compile(r"^(tcp|tls|inproc|ucx)://[^\s/]+(:\d+)?$")


def _run(args) -> int:
    from hil.campaign.engine import run_campaign
    from hil.campaign.spec import load_campaign
    from hil.campaign.summary import write_report
    if args.scheduler is not None and not SCHEDULER.match(args.scheduler):
        raise UserInputError(f"--scheduler {args.scheduler!r}: not a scheduler address (e.g. tcp://host:8786)")
    campaign = load_campaign(args.spec)                   # the whole spec is checked before anything runs
    out = output_dir(args.out or Path("hil-out") / "campaigns" / campaign.name)
    summary = run_campaign(campaign, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume)
    from hil.campaign.engine import read_results
    rows = read_results(out)
    summary["report"] = str(write_report(out, rows, summary, campaign.metrics, plots=not args.no_plots,
                                         compare=campaign.compare, controller_config=campaign.controller_config))
    if args.json:
        from hil.campaign.summary import summarize
        print(json.dumps({**summary, "metrics": summarize(rows, campaign.metrics)}, indent=1, default=str))
    else:
        print(f"campaign {campaign.name}: {summary['runs']} runs, {summary['ok']} ok, {summary['failed']} failed, "
              f"{summary['hung']} hung, {summary['spoiled']} spoiled by load, {summary['error']} errors; "
              f"{summary['runs_per_minute']} runs/min on "
              f"{summary['workers']} workers; {summary['report']}")
    return 0 if summary["ok"] == summary["runs"] else 1


def _check(args) -> int:
    from hil.campaign.spec import load_campaign
    campaign = load_campaign(args.spec)
    runs = campaign.runs()
    print(f"campaign {campaign.name}: {campaign.scenario}{' --short' if campaign.short else ''}, {len(runs)} runs")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    campaign = sub.add_parser("campaign", help="sweeps and Monte-Carlo of whole HIL runs, on this machine or a "
                                               "Dask cluster")
    campaign_sub = campaign.add_subparsers(dest="campaign_command", required=True, metavar="SUBCOMMAND",
                                           parser_class=type(campaign))
    p = campaign_sub.add_parser("run", help="run a campaign spec (hil/campaigns/*.toml)")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786); default: a LocalCluster here")
    p.add_argument("--workers", type=number_in_range(int, 1, 256), default=2,
                   help="LocalCluster worker processes (default 2; each run is three processes)")
    p.add_argument("--out", metavar="DIR", help="output directory (default: hil-out/campaigns/NAME)")
    p.add_argument("--resume", action="store_true", help="skip the runs whose parameters already have a row")
    p.add_argument("--no-plots", action="store_true", help="the report without its PNG figures")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(handler=_run)
    p = campaign_sub.add_parser("check", help="check a spec and count its runs, running nothing")
    p.add_argument("spec", metavar="SPEC")
    p.set_defaults(handler=_check)
