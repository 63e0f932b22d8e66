"""The ``workbench`` command line: every command, its options and an example in its ``--help``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from adapters.formats import FORMATS, log_suffixes
from workbench.cli.collect import add_collect
from workbench.cli.context import Context
from workbench.cli.data import cmd_import, cmd_inspect, cmd_map, cmd_simulate
from workbench.cli.model import cmd_fit, cmd_predict
from workbench.cli.options import (
    DEFAULT_MAPPING,
    MAX_WORKERS,
    SAMPLE_LOGS,
    count_arg,
    fit_n_components_arg,
    fraction_arg,
    horizon_arg,
    int_list,
    int_range,
    online_horizon_arg,
    positive_float,
    positive_int,
    seconds_arg,
    seed_arg,
    speed_arg,
    task_arg,
    timing_arg,
)
from workbench.cli.stdio import input_formats, output_formats
from workbench.cli.study import cmd_demo, cmd_evaluate, cmd_report
from workbench.cli.view import VIEW_SAMPLES, cmd_live, cmd_replay, cmd_view
from workbench.defaults import (
    DEFAULT_N_COMPONENTS,
    HORIZON_S,
    N_COMPONENTS,
    N_STEPS,
    OBJECTIVE_RESAMPLES,
    ONLINE_HORIZON_S,
    PLANT_CHOICES,
    STUDY_SAMPLES,
    TIMING,
)
from workbench.models.registry import REGISTRY

__all__ = ['build_parser']

# -- parser ------------------------------------------------------------------------------------------------
_EPILOG = """\
examples:
  workbench demo                                   # sample logs → models, report and out/demo.rrd
  workbench inspect sample_logs/landing_s00.tlog   # streams, rates, fields, time span
  workbench import sample_logs/*.tlog --mapping planar_quadrotor -o demos.parquet
  workbench fit demos.parquet --label CS1 -o cs1.npz
  workbench view demos.parquet --model CS1=cs1.npz --save session.rrd && rerun session.rrd
  workbench replay demos.parquet --model cs1.npz --speed 2
"""


class _OldSpelling(argparse.Action):
    """An option under its glossary word (its first string) that still takes its old spelling (the second) and
    says so in one line on standard error when the old one is used."""

    def __call__(self, parser, namespace, values, option_string=None):
        if option_string is not None and option_string != self.option_strings[0]:
            print(f"warning: {option_string} is the old spelling of {self.option_strings[0]} (still accepted)",
                  file=sys.stderr)
        setattr(namespace, self.dest, values)


def _common(p: argparse.ArgumentParser, *, top: bool = False) -> None:
    default = False if top else argparse.SUPPRESS
    p.add_argument("--debug", action="store_true", default=default, help="show the traceback of an error")
    p.add_argument("-q", "--quiet", action="store_true", default=default, help="print nothing but warnings and errors")


def _study_options(
    p: argparse.ArgumentParser, *, samples: int = STUDY_SAMPLES, efficiency: str | None = "2,5,10,20", repeats: int = 2
) -> None:
    p.add_argument("--test-size", type=fraction_arg, default=0.2, metavar="F",
                   help="fraction of each strategy's trials held out for testing (default 0.2)")
    p.add_argument("--horizon", dest="horizon_s", type=horizon_arg, default=HORIZON_S, metavar="SECONDS",
                   help=f"prediction horizon in seconds (default {HORIZON_S}, the paper's {N_STEPS} steps)")
    _n_components_option(p, DEFAULT_N_COMPONENTS, "as `workbench fit` builds it", "each strategy's training trials")
    p.add_argument("--samples", type=count_arg, default=samples, metavar="N",
                   help=f"Monte Carlo rollouts for the prediction band; 0 turns it off (default {samples})")
    p.add_argument("--efficiency", type=int_list, default=int_list(efficiency) if efficiency else None,
                   metavar="N,N,…", help=f"training-set sizes of the data-efficiency curve (default {efficiency})")
    p.add_argument("--no-efficiency", dest="efficiency", action="store_const", const=None,
                   help="skip the data-efficiency curve")
    p.add_argument("--repeats", type=positive_int, default=repeats, metavar="R",
                   help=f"random training subsets per size on the data-efficiency curve (default {repeats})")
    p.add_argument("--stride", dest="stride_s", type=seconds_arg, default=1.0, metavar="SECONDS",
                   help="score predictions from every SECONDS of each test trial whose record covers the horizon, "
                        "and from its first state (default 1.0)")
    p.add_argument("--first-state-only", dest="stride_s", action="store_const", const=None,
                   help="score one prediction per test trial, from its first state (the paper's)")
    p.add_argument("--keep-still", action="store_true",
                   help="keep segments in which no input moves beyond its resolution (default: reported and left "
                        "out: no pilot was flying them)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the split, EM and Monte Carlo (default 0)")
    p.add_argument("--explain", action="store_true",
                   help="print at length which number answers which question (default: a legend of one line per "
                        "question; a report holds the full text)")
    _plant_option(p)


def _n_components_option(p: argparse.ArgumentParser, default: str | None, which: str, over: str,
                         more: str = "") -> None:
    """``--n-components`` of the commands that build the default model (``which``: who else builds or judges it;
    ``over``: the trials it cross-validates on)."""
    p.add_argument("--n-components", type=fit_n_components_arg, default=default, metavar="G|bic|cv|paper",
                   help=f"cv (default: the default model, {which}) chooses G (1, 2 or 5) and the regularizer by "
                        f"cross-validation on {over} (held-out 3 s predictions) and falls back to the task "
                        "objective's K̂x where its variability model does not lower the held-out error by more than "
                        "its standard error, or, fitted on all trials, predicts them worse than K̂x (said in the "
                        f"output); paper: the paper's G = {N_COMPONENTS} without cross-validation; a number G; bic: G "
                        f"by BIC.{more}")


def _plant_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", "--system", dest="plant", action=_OldSpelling,
                   choices=PLANT_CHOICES, default="auto",
                   help="plant (A, B): the paper's planar quadrotor, identified from the data by least squares, "
                   "or auto (the paper's for its state layout at dt 0.05 s, else identified). An identified plant "
                   "that fails its physics check is identified again with the failing entries held at their physics "
                   "unless held-out segments show it worse (the held plant's one-step squared error above the free "
                   "fit's, 95 %% HAC interval), and refused where they do; as-fitted: take the least-squares plant as "
                   "fitted, physics check or not")


def _plant_group_option(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--plant-group", metavar="GROUP",
                   help="only the segments of this plant group (what the sticks command in their flight mode: angle, "
                        "angle+climb, velocity+climb, rate, surface, bank, …); default: every group the data hold, "
                        f"{what}")


def _output_options(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--save", metavar="FILE.rrd",
                   help="write a rerun recording (without a display the default is out/<input>.rrd); - for standard "
                        "output")
    g.add_argument("--spawn", action="store_true", help="stream to a native rerun viewer")
    g.add_argument("--serve", action="store_true", help="serve a web viewer on 127.0.0.1 (localhost only)")


def _executor_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scaling out (Dask)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--workers", type=int_range(1, MAX_WORKERS), metavar="N",
                   help="run independent tasks on a local Dask cluster of N worker processes (default: serial, "
                        "in this process)")
    x.add_argument("--scheduler", metavar="ADDRESS",
                   help="run them on a running Dask cluster, e.g. tcp://10.0.0.5:8786 (its workers need the "
                        "workbench and must reach the input files and --staging)")
    g.add_argument("--staging", metavar="DIR",
                   help="folder where data for the workers is written (default a temporary folder; on a cluster, "
                        "a path every worker reaches)")


_TABLE_OUTPUTS = ["parquet", "csv"]


def _format_option(p: argparse.ArgumentParser) -> None:
    names = input_formats()  # the declared log formats (adapters.formats) and parquet
    p.add_argument("--format", choices=names, metavar="FORMAT",
                   help="what the input holds (a file or - for standard input): " + ", ".join(names) +
                        " (default: recognised from its first bytes)")


def _output_format_option(p: argparse.ArgumentParser, choices: list[str]) -> None:
    p.add_argument("--output-format", choices=choices, metavar="FORMAT",
                   help=f"with -o - (standard output): {', '.join(choices)} (default parquet; binary output to a "
                        "terminal is refused)")


def _mapping_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mapping", metavar="M",
                   help="channel mapping for raw logs: a shipped name or a TOML file (default: the shipped mapping "
                        f"made for the vehicle the log names, else {DEFAULT_MAPPING}; the choice is printed)")


def build_parser() -> argparse.ArgumentParser:
    from workbench import __version__

    parser = argparse.ArgumentParser(
        prog="workbench",
        description="Models of how a human operator flies, from teleoperation and flight logs: u = K x + w, "
        "K from inverse optimal control, w from a task-parameterized GMM read out by GMR.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"workbench {__version__}")
    _common(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def add(name: str, func: Callable[[Context], int], help: str, example: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help, epilog=f"example:\n  {example}",
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        _common(p)
        p.set_defaults(func=func)
        return p

    p = add("simulate", cmd_simulate, "simulate landing demonstrations with synthetic operators",
            "workbench simulate --strategy CS1 CS2 --trials 30 -o demos.parquet")
    p.add_argument("-o", "--output", metavar="FILE", help="demonstrations file: .parquet or a log ("
                   f"{', '.join(f.suffix for f in FORMATS.values() if f.writable)}); - for standard output")
    _output_format_option(p, output_formats())
    p.add_argument("--strategy", nargs="+", default=["CS1", "CS2"], choices=["CS1", "CS2"],
                   help="control strategies: CS1 centre first, CS2 straight line (default both)")
    p.add_argument("--trials", type=int, default=30, help="trials per strategy and subject (default 30)")
    p.add_argument("--subjects", type=count_arg, default=0,
                   help="number of synthetic subjects; 0 = the reference expert")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--sample-logs", metavar="DIR", help="instead: regenerate the sample logs into DIR")

    p = add("inspect", cmd_inspect, "show what a log contains: streams, rates, fields, time span",
            "workbench inspect flight.tlog")
    p.add_argument("log", help=f"a {', '.join(log_suffixes())} log or a demonstrations .parquet; - reads standard "
                   "input")
    _format_option(p)

    p = add("import", cmd_import, "turn logs into one demonstrations file, or many logs into a partitioned dataset",
            "workbench import 'logs/*.tlog' --mapping planar_quadrotor -o dataset/ --workers 2")
    p.add_argument("logs", nargs="+", metavar="LOG|DIR|GLOB",
                   help="log files, directories of logs, or quoted glob patterns; - reads one log from standard "
                        "input")
    _mapping_option(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE|DIR/",
                   help="a demonstrations file (.parquet, .csv, …), - for standard output, or DIR/ for a dataset with "
                        "one Parquet file per log and subject, imported in parallel; a log that fails is reported and "
                        "the rest imported")
    _output_format_option(p, output_formats())
    _format_option(p)
    # --set-label: on `import` the label is written, everywhere else --label filters; the old spelling still works
    p.add_argument("--set-label", "--label", dest="label", metavar="LABEL", help="set every trial's strategy label")
    _executor_options(p)

    p = add("fit", cmd_fit, "fit a human behavior model (task objective + variability) to demonstrations",
            "workbench fit demos.parquet --label CS1 -o cs1.npz")
    p.add_argument("demos", metavar="DEMOS", help="demonstrations (.parquet) or a raw log (with --mapping); - reads "
                   "standard input")
    p.add_argument("-o", "--output", required=True, metavar="MODEL.npz", help="the model file; - for standard output")
    _format_option(p)
    p.add_argument("--label", help="fit only the trials of this strategy label")
    _n_components_option(p, None, "the one evaluate and report judge", "the trials",
                         " Baselines take the paper's G unless a number is given.")
    p.add_argument("--method", choices=[m.cli_name for m in REGISTRY if m.fit_command], default="proposed",
                   help="the proposed model (default) or one of its baselines")
    p.add_argument("--keep-still", action="store_true",
                   help="keep segments in which no input moves beyond its resolution (default: reported and left "
                        "out: no pilot was flying them)")
    p.add_argument("--gain", choices=["iv-or-direct", "direct", "dmd", "iv"], default="iv-or-direct",
                   help="how K̂ is estimated: instrumental variables where their instruments are relevant, else least "
                        "squares (iv-or-direct, default; the choice and its reason are printed), least squares "
                        "(direct), the paper's DMD, or instrumental variables only (iv: consistent when the "
                        "operator's variability is autocorrelated)")
    p.add_argument("--timing", type=timing_arg, default=TIMING, metavar="identify|none|DELAY,LAG",
                   help="the pilot's reaction delay and neuromuscular lag: identified and used by the gain, the "
                        "objective and every prediction (identify, default; printed with intervals), none (the "
                        "paper's u = K x), or given in seconds (e.g. 0.2,0.08)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the k-means initialization (default 0)")
    p.add_argument("--bootstrap", type=count_arg, default=OBJECTIVE_RESAMPLES, metavar="N",
                   help=f"resample the trials N times (default {OBJECTIVE_RESAMPLES}; 0: no intervals) and print 95 "
                        "%% intervals of K̂, the normalized Q, R diagonals and the weight ratios inside coupled parts "
                        "(the paper gives none)")
    _task_option(p)
    _power_option(p, 0)
    _plant_option(p)
    _plant_group_option(p, "a model of each written beside -o as MODEL.GROUP.npz")
    _mapping_option(p)
    _selection_options(p, "fit")
    _executor_options(p)

    p = add("predict", cmd_predict, "predict a trajectory with a fitted model from a recorded or given state",
            "workbench predict --model cs1.npz demos.parquet --demo s00-cs1-003 --horizon 3 --samples 200 -o p.csv")
    p.add_argument("demos", nargs="?", metavar="DEMOS", help="demonstrations to take the start state from; - reads "
                   "standard input")
    p.add_argument("--model", required=True, metavar="MODEL.npz", help="a fitted model; - reads standard input")
    _format_option(p)
    p.add_argument("--demo", metavar="ID", help="trial to start from (default the first)")
    p.add_argument("--start", type=count_arg, default=0, metavar="K",
                   help="sample of the trial to start from (default 0)")
    p.add_argument("--x0", metavar="X,Y,…", help="instead of a trial: the start state, comma-separated")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    p.add_argument("--horizon", dest="horizon_s", type=horizon_arg, default=HORIZON_S, metavar="SECONDS",
                   help=f"prediction horizon in seconds (default {HORIZON_S})")
    p.add_argument("--samples", type=count_arg, default=0, metavar="N",
                   help="Monte Carlo rollouts: adds <state>_lower/_upper band columns (5–95 %%)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the Monte Carlo draws (default 0)")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help=".csv or .parquet; - for standard output")
    _output_format_option(p, _TABLE_OUTPUTS)
    _mapping_option(p)
    _selection_options(p, "look")

    p = add("evaluate", cmd_evaluate,
            "compare the proposed model with IOC-only, GMR-only and persistence on held-out trials; data efficiency",
            "workbench evaluate demos.parquet --horizon 3 -o results.csv")
    p.add_argument("demos", nargs="+", metavar="DEMOS", help="demonstrations or logs; - reads one from standard input")
    p.add_argument("--label", nargs="+", help="strategy labels to evaluate (default all)")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="tidy results table (.csv or .parquet); - for standard output")
    _output_format_option(p, _TABLE_OUTPUTS)
    _format_option(p)
    p.add_argument("--per-subject", action="store_true",
                   help="the paper's multi-subject design: a model per subject, --n-test held-out trials each "
                        "(a collected session's recorded test trials with --holdout auto), "
                        "ANOVA and paired t-tests across the methods (use --horizon 5 for the paper's)")
    p.add_argument("--n-test", type=positive_int, default=1, metavar="N",
                   help="held-out trials per subject with --per-subject (default 1)")
    _holdout_option(p)
    _study_options(p)
    _plant_group_option(p, "each evaluated on its own plant (with -o, a table per group: FILE.GROUP.parquet)")
    _mapping_option(p)
    _selection_options(p, "study")
    _executor_options(p)

    p = add("map", cmd_map, "draft a mapping from a log: the vehicle, its firmware's field names, the streams "
            "for positions, velocities, attitude and sticks", "workbench map flight.tlog -o flight.toml")
    p.add_argument("log", metavar="LOG", help="the log; - reads standard input")
    p.add_argument("-o", "--output", metavar="MAPPING.toml", help="write the mapping here (default, or -: print it)")
    _format_option(p)

    p = add("view", cmd_view, "log demonstrations (and a model's variability and predictions) to rerun",
            "workbench view demos.parquet --model CS1=cs1.npz --model CS2=cs2.npz --save session.rrd")
    p.add_argument("inputs", nargs="+", metavar="DEMOS_OR_LOG", help="demonstrations or logs; - reads one from "
                   "standard input")
    p.add_argument("--model", action="append", metavar="[LABEL=]MODEL.npz",
                   help="a fitted model; with LABEL= it explains the trials of that strategy (repeatable)")
    _format_option(p)
    p.add_argument("--label", nargs="+", help="show only these strategy labels")
    p.add_argument("--focus", nargs="+", metavar="ID", help="trials to predict from (default the first per label)")
    p.add_argument("--starts", nargs="+", type=count_arg, metavar="K", help="samples to predict from (default 0)")
    p.add_argument("--horizon", dest="horizon_s", type=horizon_arg, default=HORIZON_S, metavar="SECONDS",
                   help=f"prediction horizon in seconds (default {HORIZON_S})")
    p.add_argument("--samples", type=count_arg, default=VIEW_SAMPLES, metavar="N",
                   help=f"Monte Carlo rollouts for the prediction band drawn with --model (default {VIEW_SAMPLES}, "
                        "enough for its 90 %% band and fast; 0 turns the band off)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the Monte Carlo draws (default 0)")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    _plant_group_option(p, "each segment keyed by its group")
    _mapping_option(p)
    p.add_argument("--raw", action="store_true",
                   help="a raw log as it is (every stream, modes, messages), without a mapping's states; with "
                        "several logs, all of them on one clock (an overlay)")
    p.add_argument("--color-by", default="label", metavar="KEY",
                   help="one colour per strategy label (default) or per value of another key of the trials' "
                        "metadata: subject or session overlays subjects or sessions on the trials' clock")
    p.add_argument("--align", nargs="+", metavar="WHEN",
                   help="with several raw logs: where each log's 0 s is: arming, takeoff, start or seconds after its "
                        "start; one for all or one per log (default: arming where each log records one, else its "
                        "start)")
    _selection_options(p, "look")
    _output_options(p)

    p = add("replay", cmd_replay, "stream a recorded session as if live, with the model's online predictions",
            "workbench replay demos.parquet --model cs1.npz --speed 1.0 --spawn")
    p.add_argument("log", metavar="LOG", help="demonstrations (.parquet) or a raw log (with --mapping); - reads "
                   "standard input")
    p.add_argument("--model", metavar="MODEL.npz", help="the model whose online predictions are shown")
    _format_option(p)
    p.add_argument("--to", metavar="CONNECTION",
                   help="instead: send a .tlog's raw MAVLink frames to a link with their recorded timing (a stand-in "
                        "vehicle for `workbench live`), e.g. udpout:127.0.0.1:14550; no model needed")
    p.add_argument("--demo", nargs="+", metavar="ID", help="trials to replay (default the first)")
    p.add_argument("--speed", type=speed_arg, default=1.0, help="multiple of real time (default 1.0; 0.001 to "
                   "1e6)")
    p.add_argument("--no-wait", action="store_true", help="stream as fast as possible")
    p.add_argument("--horizon", dest="horizon_s", type=online_horizon_arg, default=ONLINE_HORIZON_S, metavar="SECONDS",
                   help=f"rollout horizon of the online prediction (default {ONLINE_HORIZON_S} s; 0 turns rollouts "
                        "off)")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    _mapping_option(p)
    _selection_options(p, "look")
    _output_options(p)

    p = add("live", cmd_live, "predict the pilot online from a vehicle's live MAVLink telemetry, into rerun",
            "workbench live udpin:0.0.0.0:14550 --mapping planar_quadrotor --model cs1.npz --spawn")
    p.add_argument("connection", metavar="CONNECTION",
                   help="a pymavlink connection: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or a serial device")
    p.add_argument("--model", required=True, metavar="MODEL.npz")
    p.add_argument("--duration", type=positive_float, metavar="SECONDS", help="stop after this long (default: Ctrl-C)")
    p.add_argument("--horizon", dest="horizon_s", type=online_horizon_arg, default=ONLINE_HORIZON_S, metavar="SECONDS",
                   help=f"rollout horizon at every step (default {ONLINE_HORIZON_S} s; 0 turns rollouts off)")
    p.add_argument("--sysid", type=int_range(1, 255), metavar="N",
                   help="follow this MAVLink system (default: the first vehicle)")
    p.add_argument("--clock", choices=["vehicle", "arrival"], default="vehicle",
                   help="time samples by the vehicle's time_boot_ms (default) or by their arrival")
    p.add_argument("--silence", type=positive_float, default=2.0, metavar="SECONDS",
                   help="report the link silent after this long without data (default 2 s)")
    _mapping_option(p)
    _output_options(p)

    p = add("report", cmd_report,
            "fit, compare and write a Markdown report: figures (PNG, SVG, PDF) and tables (CSV, LaTeX)",
            "workbench report demos.parquet -o report/")
    p.add_argument("demos", nargs="+", metavar="DEMOS", help="demonstrations or logs; - reads one from standard input")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="the report's folder (not -: it is a folder)")
    _format_option(p)
    p.add_argument("--label", nargs="+", help="strategy labels to include (default all)")
    p.add_argument("--title", default="Workbench report")
    _holdout_option(p)
    _bootstrap_option(p)
    _power_option(p, 1)
    _study_options(p)
    _task_option(p)
    _plant_group_option(p, "a report of each in DIR/GROUP/")
    _mapping_option(p)
    _selection_options(p, "study")
    _executor_options(p)

    p = add("demo", cmd_demo, "the whole pipeline on the sample logs: import, fit CS1 and CS2, compare, report, .rrd",
            "workbench demo --out out/ && rerun out/demo.rrd")
    p.add_argument("--out", default="out", metavar="DIR", help="output directory (default out/)")
    p.add_argument("--logs", metavar="DIR", help=f"logs to import (default {SAMPLE_LOGS})")
    _study_options(p, repeats=1)  # one subset per size keeps the demo well under a minute on two cores
    _bootstrap_option(p)
    _power_option(p, 1)
    _mapping_option(p)
    _selection_options(p, "study")

    add_collect(add)
    return parser


def _selection_options(p: argparse.ArgumentParser, purpose: str) -> None:
    """``--role``, ``--outcome``, ``--include-excluded``: which of a collected session's trials count
    (:mod:`workbench.data.selection`); the defaults are the purpose's."""
    g = p.add_argument_group("which trials (of a session recorded by `workbench collect`)")
    role = {"fit": "train", "study": "train,test (the test trials held out)", "look": "all"}[purpose]
    outcome = "all" if purpose == "look" else "landed"
    g.add_argument("--role", metavar="train|test|all",
                   help=f"the trials of these recorded roles, comma-separated (default {role}; trials that record "
                        "no role are kept)")
    g.add_argument("--outcome", metavar="landed|crashed|…|all",
                   help=f"the trials of these recorded outcomes, comma-separated: landed, crashed, left-the-domain, "
                        f"time-limit (default {outcome} on a collected session)")
    g.add_argument("--include-excluded", action="store_true",
                   help="keep the trials the experimenter marked excluded (default: left out, and said so)")


def _task_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", type=task_arg, metavar="REL[@STATES]",
                   help="what the pilot regulates, relative to what: goal, zero or reference:line / "
                        "reference:horizontal-first, optionally @state,state,… (or @inner: all but the positions); "
                        "default: decided from the trials (their goals, a reference they declare, the plant's "
                        "positions: a free flight regulates its inner loops) and printed")


def _power_option(p: argparse.ArgumentParser, default: int) -> None:
    p.add_argument("--power", type=count_arg, default=default, metavar="N",
                   help="the power curve that says how many demonstrations a weight ratio the data do not identify "
                        "would need: simulated demonstration sets per size (n/2, n, 2n) to start with — at least 3, "
                        "and more, up to 6, while the curve is not monotone; the number comes with its interval "
                        f"(default {default}; 0: none)")


def _holdout_option(p: argparse.ArgumentParser) -> None:
    """``--holdout``: one rule for ``evaluate`` and ``report``, so both score the same trials the same way."""
    p.add_argument("--holdout", choices=["auto", "split", "loso"], default="auto",
                   help="test trials: one random split (--test-size), leave-one-segment-out (every trial tested "
                        "once by models fitted on the others; no data-efficiency curve), or auto: the test trials a "
                        "collected session recorded (role test), else leave-one-out when a label has fewer than 10 "
                        "trials, else a split (default)")


def _bootstrap_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bootstrap", type=count_arg, default=OBJECTIVE_RESAMPLES, metavar="N",
                   help="resamples of each strategy's training trials for the intervals of its task objective and "
                        f"weight ratios (default {OBJECTIVE_RESAMPLES}; 0: point estimates only)")
