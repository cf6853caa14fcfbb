"""`hydrapod kinematics ...`: DK evaluation, workspace figures, dynamics validation, bench."""

from __future__ import annotations

import argparse
import json

from firmware_py.mechanics.geometry import default_geometry, load_geometry_file
from firmware_py.mechanics.workspace import MIN_CONDITION_INDEX
from program.cliutil import number_in_range, output_dir


def _geometry(args):
    return load_geometry_file(args.geometry) if args.geometry else default_geometry()


def _print(args, report, text) -> int:
    print(json.dumps(report, indent=2) if args.json else text)
    return 0


def _dk_eval(args) -> int:
    from hil.tools.dk_eval import evaluate, format_evaluation
    margin = MIN_CONDITION_INDEX if args.min_condition_index is None else args.min_condition_index
    report = evaluate(_geometry(args), int(args.samples), int(args.seed), margin)
    return _print(args, report, format_evaluation(report))


def _workspace(args) -> int:
    from hil.tools.workspace_figures import workspace_extents
    geometry = _geometry(args)
    out = output_dir(args.plot, "--plot") if args.plot else None
    report = {"extents": workspace_extents(geometry), "min_condition_index": MIN_CONDITION_INDEX}
    if out is not None:
        from hil.tools.workspace_plots import plot_workspace
        report["plots"] = [str(p) for p in plot_workspace(geometry, out, int(args.resolution))]
    text = "\n".join([f"{k:>26}: {v:8.1f}" for k, v in report["extents"].items()] +
                     [f"wrote {p}" for p in report.get("plots", [])])
    return _print(args, report, text)


def _validate_dynamics(args) -> int:
    from hil.tools.validate_dynamics import format_validation, plot_validation, validate_all
    from plant_emulator.rig_geometry import read_rig_geometry
    out = output_dir(args.plot, "--plot") if args.plot is not None else None     # before the work
    series = []
    rows = validate_all(_geometry(args), read_rig_geometry(args.geometry), series)
    report = {"trajectories": rows}
    text = format_validation(rows)
    if out is not None:
        report["figures"] = [str(out / name) for name in plot_validation(rows, series, out)]
        text += f"\nwrote {', '.join(report['figures'])}"
    return _print(args, report, text)


def _bench(args) -> int:
    from hil.tools.kinematics_bench import format_bench, run_bench
    report = run_bench(_geometry(args), int(args.calls))
    return _print(args, report, format_bench(report))


def add_parsers(sub: argparse._SubParsersAction) -> None:
    kin = sub.add_parser("kinematics", help="mechanism: direct kinematics, workspace, dynamics validation, bench")
    kin_sub = kin.add_subparsers(dest="kinematics_command", required=True, metavar="SUBCOMMAND",
                                 parser_class=type(kin))

    def common(parser):
        parser.add_argument("--geometry", metavar="FILE", help="geometry TOML (default: the rig's, in the package)")
        parser.add_argument("--json", action="store_true", help="print JSON")

    p = kin_sub.add_parser("dk-eval", help="direct kinematics performance like thesis Table 9.1")
    p.add_argument("--samples", type=number_in_range(int, 1, 10_000_000), default=10000)
    p.add_argument("--seed", type=number_in_range(int, 0, 2**32 - 1), default=1)
    p.add_argument("--min-condition-index", type=number_in_range(float, 0.0, 1.0), default=None,
                   help="singularity margin of the sampled workspace, 1/cond(Jx) (default: the rig's "
                        "limit; 0 samples everything on the home side of the singular surface)")
    common(p)
    p.set_defaults(handler=_dk_eval)

    p = kin_sub.add_parser("workspace", help="workspace extents (chapter 9.3) and slice plots (Figs. 9.3-9.12)")
    p.add_argument("--plot", metavar="DIR", help="write PNG slices into DIR")
    p.add_argument("--resolution", type=number_in_range(int, 11, 401), default=81, help="grid points per axis")
    common(p)
    p.set_defaults(handler=_workspace)

    p = kin_sub.add_parser("validate-dynamics", help="inverse dynamics vs the MuJoCo model, Table 10.2")
    p.add_argument("--plot", metavar="DIR", help="write Fig. 10.3's errors and Figs. E.1-E.6's forces into DIR")
    common(p)
    p.set_defaults(handler=_validate_dynamics)

    p = kin_sub.add_parser("bench", help="per-call time and allocations of IK, DK and inverse dynamics")
    p.add_argument("--calls", type=number_in_range(int, 100, 10_000_000), default=20000)
    common(p)
    p.set_defaults(handler=_bench)
