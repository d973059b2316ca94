"""What every command shares: the parser and its help, output on stdout and stderr, and the
one place where the library's field names become the command line's flags."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn, TypeVar

from brdf_infer.cli._device import DEVICES
from brdf_infer.cli._outdir import claim_output_dir
from brdf_infer.errors import BadInputError
from brdf_infer.runs.records import PosteriorSummary

EXIT_BAD_INPUT = 2
T = TypeVar("T")
# fields of an option that names a folder: its errors name the folder as their file
FOLDER_OPTIONS = frozenset({"out", "resume", "run"})


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error in one line (exit code 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows every option's default (a None or False default is left unsaid)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default is None or action.default is False or action.default == argparse.SUPPRESS:
            return action.help or ""
        return super()._get_help_string(action)


def _common_options() -> argparse.ArgumentParser:
    """The options of every command (``--no-cache``, ``--device``)."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the persistent compilation cache (BRDF_INFER_CACHE, else "
        "~/.cache/brdf_infer) for this run",
    )
    common.add_argument(
        "--device",
        choices=DEVICES,
        default="auto",
        help="where to compute: auto keeps single-scene work (run, posterior, fit, ...) on "
        "the CPU, where a small posterior is fastest, and gives batch, sbc, raytrace and "
        "bench the accelerator when JAX has one",
    )
    return common


def command_parser(commands, name: str, help_text: str) -> argparse.ArgumentParser:
    """The parser of the subcommand ``name``, with the options every command has."""
    return commands.add_parser(
        name,
        help=help_text,
        description=help_text,
        formatter_class=HelpFormatter,
        parents=[_common_options()],
    )


def scene_command_parser(commands, name: str, help_text: str) -> argparse.ArgumentParser:
    """:func:`command_parser` with the scene argument and ``--json``."""
    parser = command_parser(commands, name, help_text)
    parser.add_argument("scene", nargs="?", default="lya", help="built-in name or TOML path")
    add_json_argument(parser)
    return parser


def add_json_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")


def add_nuts_arguments(
    parser: argparse.ArgumentParser,
    defaults: type,
    *,
    per: str = "chain",
    helps: dict[str, str] | None = None,
) -> None:
    """The NUTS options of a command, one per field of its settings record ``defaults`` that
    it has (``chains``, ``draws``, ``warmup``, ``seed``, ``target_accept``), with the record's
    defaults; ``per``: what one warmup and one set of draws belong to (chain, replicate);
    ``helps``: a field's own help text where the command says more."""
    fields = {field.name for field in dataclasses.fields(defaults)}
    options = {
        "chains": (int, "NUTS chains"),
        "draws": (int, f"NUTS draws per {per}"),
        "warmup": (int, f"NUTS warmup per {per}"),
        "seed": (int, "random seed"),
        "target_accept": (float, "NUTS target acceptance probability"),
    }
    for name, (kind, help_text) in options.items():
        if name in fields:
            help_text = (helps or {}).get(name, help_text)
            parser.add_argument(
                flag(name), type=kind, default=getattr(defaults, name), help=help_text
            )


def flag(field: str) -> str:
    """The option of a settings record's field: ``target_accept`` → ``--target-accept``."""
    return "--" + field.replace("_", "-")


def record_from_args(record: type[T], args: argparse.Namespace, **computed: Any) -> T:
    """The settings ``record`` (a dataclass) from the command's options: each field from the
    option of its name (:func:`flag`), the fields in ``computed`` from those values instead
    (an option that is not the field itself, e.g. ``refit=not args.no_refit``); a field with
    no option keeps its default."""
    options = vars(args)
    values = {
        field.name: options[field.name]
        for field in dataclasses.fields(record)
        if field.name in options and field.name not in computed
    }
    return record(**values, **computed)


def named_by_flag(error: BadInputError, args: argparse.Namespace) -> BadInputError:
    """``error`` with its field named as the option that set it (``warmup`` → ``--warmup``),
    where the field is one of the command's options; a field of a file's contents (a scene
    key, a CSV column) keeps its name."""
    field = error.field
    options = vars(args)
    if field is None or field.startswith("-") or field not in options:
        return error
    if error.file is not None and field not in FOLDER_OPTIONS:
        return error
    return BadInputError(
        error.problem, file=error.file, row=error.row, line=error.line, field=flag(field)
    )


def claimed_output_dir(args: argparse.Namespace, path: str | Path, command: str) -> Path:
    """``path``, held for ``command`` until the command ends (one writer per folder)."""
    return claim_output_dir(path, command, args.claims, option="--out")


def headless() -> None:
    """Figures are written to files, never shown: the non-interactive backend, set here and
    not on import, so that notebooks keep their inline figures."""
    import matplotlib

    matplotlib.use("Agg")


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def emit_json(content: dict[str, Any]) -> None:
    print(json.dumps(content))


def table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A right-aligned text table."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    return "\n".join(lines)


def print_verdict(verdict: dict[str, Any]) -> None:
    """The run's one verdict (:mod:`brdf_infer.verdict`), as its report shows it."""
    print(f"verdict: {verdict['text']}")


EXIT_MODEL_REJECTED = 3  # --strict-model: the run was written, but the data reject its model


def add_strict_model_argument(parser: argparse.ArgumentParser) -> None:
    """``--strict-model``: exit :data:`EXIT_MODEL_REJECTED` where the model check fails."""
    parser.add_argument(
        "--strict-model",
        action="store_true",
        help=f"exit with code {EXIT_MODEL_REJECTED} (after writing every file) where the data "
        "reject the model (summary.json model_check.ok false), for pipelines",
    )


def model_exit_code(args: argparse.Namespace, summary: PosteriorSummary) -> int:
    """0, or :data:`EXIT_MODEL_REJECTED` with ``--strict-model`` where the run's model check
    failed (a run written before the record: 0)."""
    record = summary.get("model_check")
    rejected = record is not None and not record["ok"]
    return EXIT_MODEL_REJECTED if getattr(args, "strict_model", False) and rejected else 0


def print_posterior_summary(summary: PosteriorSummary, out: Path) -> None:
    """A posterior run's parameters with their diagnostics, TIS(70°) and times."""
    diagnostics = summary["diagnostics"]
    judged = summary.get("learned", {})
    rows = [
        [
            name,
            f"{values['mean']:.4g}",
            f"{values['sd']:.2g}",
            f"{values['r_hat']:.3f}",
            f"{values['ess_bulk']:.0f}",
            f"{values['ess_tail']:.0f}",
            judged[name]["words"] if name in judged else "-",
        ]
        for name, values in diagnostics["parameters"].items()
    ]
    print(
        f"posterior of scene '{summary['scene']}', model {summary['model']} ({summary['sampler']})"
    )
    headers = ["parameter", "mean", "sd", "R-hat", "ESS bulk", "ESS tail", "from the data"]
    print(table(headers, rows))
    tis70 = summary["tis_70deg"]
    if tis70 is not None:
        from brdf_infer.verdict import TARGET_WORDS

        print(
            f"TIS(70 deg) = {100 * tis70['median']:.2f} % "
            f"(95 %: {100 * tis70['lo95']:.2f}-{100 * tis70['hi95']:.2f} %; "
            f"{'with' if summary['fold'] else 'without'} Eq. (10) folding) for "
            f"{TARGET_WORDS[summary.get('target', 'coating')]}"
        )
        width = summary.get("width", {}).get("tis_70deg")
        if width and width.get("without"):
            from brdf_infer.verdict import width_words

            whose = "its" if summary.get("target", "coating") == "coating" else "the coating's"
            print(f"  what carries {whose} width: {width_words(width, 'tis_70deg')}")
    seconds = summary["seconds"]
    print(
        f"posterior: {seconds['total']:.1f} s from building the model to its files, "
        f"{seconds['sampling']:.1f} s of it sampling; results in {out}/"
    )
