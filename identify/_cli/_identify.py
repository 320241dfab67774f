"""`jaxunilat identify`: fit κ and k_r to a data file and report them with uncertainty."""

from __future__ import annotations

from jaxunilat._internal import EXIT_NOT_CONVERGED, InputError


def default_data_path() -> str:
    """The bundled default data set, `data/drop_trace.csv` (a synthetic 1 kHz drop test)."""
    from jaxunilat._internal import bundled_data

    found = bundled_data("drop_trace.csv")
    if found:
        return found[0]
    raise InputError(
        "no DATA given and the bundled data/drop_trace.csv was not found (it installs with the package as jaxunilat/_data, and is data/ in a checkout); "
        "pass a data file: jaxunilat identify DATA.csv"
    )


def register(commands) -> None:
    """Add `identify` to the `jaxunilat` subparsers (a line of `jaxunilat._cli._main.COMMANDS`)."""
    p = commands.add_parser(
        "identify",
        help="fit contact stiffness kappa and damping k_r to rebound data, with uncertainty",
        description="Fit kappa and k_r of the ball model [K90 Eq. 3.1-3.3] to one or several rebound data "
        "files (format: data/README.md; `jaxunilat import` converts recordings) with the event mode; report "
        "estimates, 95% CIs, derived e and t_c, correlations, outliers and an identifiability verdict. "
        "Several files are fitted jointly: kappa, k_r (and drag) shared, each file its own x0, v0, offset "
        "(and a trace's scale, level). The clock offset of impact onsets, and a trace's length scale and "
        "contact level, are fitted by default (--freeze offset, --freeze scale,level hold them). Exit status: 0 "
        "converged, 3 not converged or contradicted by the data's own closed-form restitution or release "
        "height (the JSON is still written, with converged: false and the reasons), 2 bad input.",
    )
    p.add_argument(
        "data",
        nargs="*",
        metavar="DATA.csv",
        help="data files, fitted jointly (default: the bundled data/drop_trace.csv)",
    )
    p.add_argument("--json", metavar="OUT.json", help="write the fit as JSON")
    p.add_argument("--plot", metavar="OUT.png", help="draw the data against the fit, with residuals and e(v)")
    p.add_argument("--starts", type=int, default=3, help="number of starts (default 3)")
    p.add_argument(
        "--fit",
        default="",
        metavar="NAMES",
        help="nuisance parameters to fit too, comma-separated from drag,x0,v0,offset,scale,level (offset: the "
        "recording's unknown time origin, for impact onsets and traces; scale, level: a trace's length scale and "
        "contact level, data = level + scale * model position, fitted by default for traces)",
    )
    p.add_argument(
        "--freeze",
        default="",
        metavar="NAMES",
        help="parameters held at their file values, comma-separated from kappa,k_r,drag,x0,v0,offset,scale,level "
        "(e.g. offset, when impact onsets are timed from the release; scale,level (held at 1, 0) when a trace's "
        "calibration was measured; by default the offset of impact onsets and a trace's scale and level are "
        "fitted)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the starts' jitter (default 0)")
    p.add_argument("--method", choices=("lm", "optax"), default="lm", help="lm (default) or optax then lm")
    p.add_argument(
        "--law",
        choices=("kelvin-voigt", "hunt-crossley", "auto"),
        default="kelvin-voigt",
        help="contact law: kelvin-voigt (default, the paper's), hunt-crossley (n = 3/2: e falls with impact "
        "speed), or auto (fit both, compare chi-square, AIC and BIC, keep the lower BIC)",
    )
    p.add_argument(
        "--keep-outliers",
        action="store_true",
        help="fit every row by least squares (default: a robust Cauchy pass, then rows beyond "
        "--outlier-threshold robust sd are excluded and listed)",
    )
    p.add_argument(
        "--outlier-threshold",
        type=float,
        default=4.0,
        metavar="K",
        help="exclude rows beyond K robust residual sd (1.4826 x median |residual|); default 4",
    )
    p.add_argument(
        "--holdout",
        type=float,
        default=0.0,
        metavar="F",
        help="fit the first (1 - F) of each file's rows and predict the rest (0 <= F < 1; default 0)",
    )
    p.add_argument("--profile", action="store_true", help="also compute the profile likelihood of kappa")
    p.add_argument(
        "--mass",
        type=float,
        metavar="KG",
        help="the ball's mass, kg, replacing every data file's (the report and the JSON say so, with the file's "
        "value); the drag stays the file's unless --drag is given",
    )
    p.add_argument(
        "--drag",
        type=float,
        metavar="S_PER_M",
        help="quadratic drag k = 1/terminal speed, s/m, replacing every data file's (held, or the start of a "
        "fit with --fit drag)",
    )
    p.set_defaults(func=_run_identify)


def _names(text: str, flag: str, valid, what: str) -> tuple[str, ...]:
    """The comma-separated names of `flag`, each checked against `valid`."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    for name in names:
        if name not in valid:
            raise InputError(f"{flag} {name!r} is not {what}; valid: {', '.join(valid)}")
    return names


def _checked_arguments(args) -> tuple[tuple[str, ...], tuple[str, ...], list[str]]:
    """`--fit`, `--freeze` and the data paths, checked with the outputs before any work."""
    from jaxunilat._internal import check_output_paths, check_plot_format, check_range, input_errors

    from .. import NUISANCE, PARAMETERS

    nuisance = _names(args.fit, "--fit", NUISANCE, "a nuisance parameter")
    freeze = _names(args.freeze, "--freeze", PARAMETERS, "a parameter")
    if args.starts < 1:
        raise InputError(f"--starts {args.starts} is out of range; valid range is integers >= 1")
    if args.seed < 0:
        raise InputError(f"--seed {args.seed} is out of range; valid range is integers >= 0")
    check_range("--mass", args.mass, lo=0.0, lo_open=True, unit="kg", allow_none=True)
    check_range("--drag", args.drag, lo=0.0, unit="s/m", allow_none=True)
    paths = list(args.data) or [default_data_path()]
    inputs = [(f"DATA {i + 1}" if len(paths) > 1 else "DATA", path) for i, path in enumerate(paths)]
    with input_errors():
        check_output_paths(("--json", args.json), ("--plot", args.plot), inputs=inputs)
    check_plot_format(args.plot)
    return nuisance, freeze, paths


def _run_identify(args) -> int:
    import dataclasses
    import json

    from jaxunilat._internal import input_errors, output_errors, printable, write_atomically

    from .. import fit, load_dataset

    nuisance, freeze, paths = _checked_arguments(args)
    with input_errors():
        data = [load_dataset(path) for path in paths]
        data, overrides = _overridden(data, mass=args.mass, drag=args.drag)
    result = fit(
        data if len(data) > 1 else data[0],
        nuisance=nuisance,
        freeze=freeze,
        starts=args.starts,
        seed=args.seed,
        method=args.method,
        profile=args.profile,
        progress=True,
        law=args.law,
        keep_outliers=args.keep_outliers,
        outlier_threshold=args.outlier_threshold,
        holdout=args.holdout,
    )
    result = dataclasses.replace(result, notes=(*(o["note"] for o in overrides.values()), *result.notes))
    print(_terminal(result.report()))
    if args.json is not None:
        doc = result.to_json_dict()
        doc["overrides"] = {
            name: {k: v for k, v in o.items() if k != "note"} for name, o in overrides.items()
        }
        with output_errors("--json", args.json):
            with write_atomically(args.json, encoding="utf-8") as fh:
                json.dump(doc, fh, indent=2, allow_nan=False)
        print(f"wrote {printable(args.json)}")
    if args.plot is not None:
        from jaxunilat.plot import save_figure

        from ..plot import plot_fit

        figure = plot_fit(result)
        with output_errors("--plot", args.plot):
            save_figure(figure, args.plot)
        print(f"wrote {printable(args.plot)}")
    return _verdict(result)


def _terminal(text: str) -> str:
    """`text` line by line as the terminal gets it: control characters (a file name's
    escape bytes) escaped, numbers of more than 16 digits shortened (a wild fit's e)."""
    from jaxunilat._internal import bounded_numbers, printable

    return "\n".join(bounded_numbers(printable(line)) for line in text.split("\n"))


def _overridden(data: list, **values) -> tuple[list, dict]:
    """The data sets with the fields in `values` that are not None (`mass`, `drag`) replaced,
    and per replaced field {"value", "files": the files' own values, "note": one line}."""
    import dataclasses
    import os

    units = {"mass": "kg", "drag": "s/m"}
    overrides = {}
    for name, value in values.items():
        if value is None:
            continue
        before = [float(getattr(d, name)) for d in data]
        data = [dataclasses.replace(d, **{name: value}) for d in data]
        if len(data) == 1:
            was = f"file: {before[0]:g} {units[name]}"
        else:
            was = "files: " + ", ".join(
                f"{os.path.basename(d.path or '?')} {b:g}" for d, b in zip(data, before, strict=True)
            )
            was += f" {units[name]}"
        note = f"{name} overridden: {value:g} {units[name]} ({was})"
        overrides[name] = {"value": float(value), "files": before, "note": note}
    return data, overrides


def _verdict(result) -> int:
    """Print why a fit failed, if it did; its exit status (0, or 3 for a failed fit)."""
    from jaxunilat._internal import EXIT_OK

    if result.contradictions:
        for reason in result.contradictions:
            print(_terminal(f"rejected: {' '.join(str(reason).split())}"))
        print(f"the fit contradicts its own data (nothing is identifiable): exit status {EXIT_NOT_CONVERGED}")
        return EXIT_NOT_CONVERGED
    if not result.converged:
        message = " ".join(str(result.message).split())
        print(_terminal(f"the fit did not converge ({message}): exit status {EXIT_NOT_CONVERGED}"))
        return EXIT_NOT_CONVERGED
    return EXIT_OK
