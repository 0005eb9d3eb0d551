"""The options of ``python -m fempm run`` and ``resume``: a scene builder's typed options, the
run-health limits and the stepping options every scene takes, and the usage error they raise."""

from __future__ import annotations

import dataclasses
import inspect
import math

from fempm.docstrings import arguments, first_sentence, plain
from fempm.scene.definition import Scene
from fempm.stepping.health import Health
from fempm.stepping.options import StepOptions
from fempm.transfer.transfers import TRANSFERS

__all__ = ["STEPPING_FLAGS", "UsageError", "boolean", "health_descriptions", "health_options", "one_line",
           "option_descriptions", "petsc_options", "scene_options", "split_flags", "stepping_options", "with_stepping"]


class UsageError(SystemExit):
    """A mistake in the command line: its message on one line, exit code 2, no traceback."""


def option_descriptions(builder) -> dict[str, str]:
    """Each option of a scene builder with its description, the first sentence on one line
    without markup: from the builder's own ``Args:`` section, else (the options every scene
    passes on to them) from :class:`fempm.stepping.StepOptions`'s or :class:`fempm.scene.Scene`'s;
    "" where none says."""
    docs = {**arguments(Scene), **arguments(StepOptions), **arguments(builder)}
    return {k: one_line(docs.get(k, "")) for k in inspect.signature(builder).parameters if k != "comm"}


def health_descriptions() -> dict[str, str]:
    """Each run-health limit (:class:`fempm.stepping.health.Health`) with its description, as
    :func:`option_descriptions` gives the scenes' options."""
    return {k: one_line(v) for k, v in arguments(Health).items()}


def one_line(description: str) -> str:
    """An ``Args:`` entry as the help prints it: its first sentence, without markup."""
    return first_sentence(plain(description))


def scene_options(builder, rest: list[str]) -> dict:
    """``--name value`` pairs typed after the builder's defaults; unknown names are errors."""
    signature = inspect.signature(builder).parameters
    params = {k: v.default for k, v in signature.items() if k != "comm"}
    opts = {}
    it = iter(rest)
    for flag in it:
        if not flag.startswith("--"):
            raise UsageError(f"fempm run: expected --option value, got {flag!r}")
        name = flag[2:].replace("-", "_")
        if name not in params:
            raise UsageError(f"fempm run: unknown option --{flag[2:]}; options: "
                             f"{', '.join('--' + k.replace('_', '-') for k in sorted(params))}")
        value = next(it, None)
        if value is None:
            raise UsageError(f"fempm run: option {flag} needs a value")
        default = params[name]
        if isinstance(default, bool):
            opts[name] = boolean(flag, value)
        elif isinstance(default, (int, float)):
            kind = "an integer" if isinstance(default, int) else "a number"
            try:
                opts[name] = type(default)(value)
            except ValueError:
                raise UsageError(f"fempm run: option {flag} expects {kind}, got {value!r}") from None
            if not math.isfinite(opts[name]):
                raise UsageError(f"fempm run: option {flag} expects a finite number, got {value!r}")
        elif default is None:  # an optional number, an integer where annotated so (or a name)
            kinds = [k.strip() for k in str(signature[name].annotation).split("|")]
            try:
                opts[name] = int(value) if "int" in kinds else float(value)
            except ValueError:
                if "int" in kinds:
                    raise UsageError(f"fempm run: option {flag} expects an integer, got {value!r}") from None
                opts[name] = value
            if isinstance(opts[name], float) and not math.isfinite(opts[name]):
                raise UsageError(f"fempm run: option {flag} expects a finite number, got {value!r}")
        else:
            opts[name] = value
    return opts


def boolean(flag: str, value: str) -> bool:
    """``true/false``, ``yes/no``, ``on/off``, ``1/0`` (any case) as a boolean option."""
    table = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}
    if value.lower() not in table:
        raise UsageError(f"fempm run: option {flag} expects true or false, got {value!r}")
    return table[value.lower()]


def split_flags(rest: list[str], names) -> tuple[dict[str, tuple[str, str]], list[str]]:
    """The ``--name value`` pairs of ``rest`` whose name (dashes as underscores) is in ``names``,
    as name -> (flag, value), and the other arguments in their order."""
    chosen, others = {}, []
    it = iter(rest)
    for flag in it:
        name = flag[2:].replace("-", "_") if flag.startswith("--") else ""
        if name not in names:
            others.append(flag)
            continue
        value = next(it, None)
        if value is None:
            raise UsageError(f"fempm run: option {flag} needs a value")
        chosen[name] = (flag, value)
    return chosen, others


def health_options(rest: list[str]) -> tuple[dict, list[str]]:
    """Split the run-health limits (``--energy-tolerance X|none``, ``--j-min``, ``--j-max``,
    ``--dt-floor``) from the scene options."""
    chosen, others = split_flags(rest, Health().asdict())
    health = {}
    for name, (flag, value) in chosen.items():
        if name == "energy_tolerance" and value.lower() in ("none", "off"):
            health[name] = None
            continue
        try:
            health[name] = float(value)
        except ValueError:
            raise UsageError(f"fempm run: option {flag} expects a number, got {value!r}") from None
    return health, others


def petsc_options(rest: list[str]) -> tuple[dict[str, str], list[str]]:
    """Split PETSc options (``-name value`` or ``-name`` alone, one dash, as PETSc's own command
    line: e.g. ``-fempm_implicit_pc_type gamg``) from the scene options; returns ({name: value},
    the rest). A value is the next word unless that is another option (a negative number is a
    value)."""
    options, others, i = {}, [], 0
    while i < len(rest):
        word = rest[i]
        if word.startswith("-") and not word.startswith("--") and len(word) > 1 and word[1].isalpha():
            value = rest[i + 1] if i + 1 < len(rest) else None
            if value is not None and not (value.startswith("-") and not _number(value)):
                options[word[1:]] = value
                i += 2
                continue
            options[word[1:]] = ""
        else:
            others.append(word)
        i += 1
    return options, others


def _number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


#: the stepping options every scene takes on the command line, with the values they accept
STEPPING_FLAGS = {"integrator": ("explicit", "implicit"), "dynamics": ("newmark", "quasi-static"), "steps": None,
                  "volumetric": ("standard", "fbar"), "outside": ("raise", "remove"),
                  "tangent": ("analytic", "finite-difference"), "transfer": tuple(TRANSFERS), "xpic_order": None,
                  "affine_cutoff": float}


def stepping_options(rest: list[str]) -> tuple[dict, list[str]]:
    """Split the stepping options every scene takes (``--integrator explicit|implicit``,
    ``--dynamics newmark|quasi-static``, ``--steps N``, ``--volumetric standard|fbar``,
    ``--outside raise|remove``, ``--tangent analytic|finite-difference``, ``--transfer
    flip|pic|apic|tpic|xpic``, ``--xpic-order M``, ``--affine-cutoff C``) from the scene options."""
    chosen, others = split_flags(rest, STEPPING_FLAGS)
    stepping = {}
    for name, (flag, value) in chosen.items():
        choices = STEPPING_FLAGS[name]
        if choices is float:  # --affine-cutoff
            try:
                stepping[name] = float(value)
            except ValueError:
                raise UsageError(f"fempm run: option {flag} expects a number, got {value!r}") from None
            continue
        if choices is None:  # --steps, --xpic-order
            if not (value.isdigit() and int(value) >= 1):
                what = "steps" if name == "steps" else "series terms (XPIC(1) is PIC)"
                raise UsageError(f"fempm run: option {flag} expects a positive number of {what}, got {value!r}")
            stepping[name] = int(value)
        elif value not in choices:
            raise UsageError(f"fempm run: option {flag} expects one of {', '.join(choices)}, got {value!r}")
        else:
            stepping[name] = value
    for name in ("dynamics", "tangent"):
        if stepping.get("integrator") != "implicit" and name in stepping:
            raise UsageError(f"fempm run: option --{name} applies to --integrator implicit")
    if "xpic_order" in stepping and stepping.get("transfer") != "xpic":
        raise UsageError("fempm run: option --xpic-order applies to --transfer xpic")
    if "affine_cutoff" in stepping and stepping.get("transfer") not in ("apic", "tpic"):
        raise UsageError("fempm run: option --affine-cutoff applies to --transfer apic or tpic")
    return stepping, others


def with_stepping(scene, stepping: dict):
    """``scene`` with the command line's stepping options: the integrator and its dynamics
    (quasi-static: the loads ramped to ``t_end``), ``--steps`` fixed steps to ``t_end``."""
    if not stepping:
        return scene
    if "outside" in stepping:
        scene.outside = stepping["outside"]
    changes = {k: stepping[k] for k in ("integrator", "dynamics", "volumetric", "tangent", "transfer", "xpic_order",
                                   "affine_cutoff") if k in stepping}
    if stepping.get("integrator") == "implicit" and stepping.get("dynamics") == "quasi-static":
        changes["load_ramp"] = scene.t_end
    if changes:
        scene.options = dataclasses.replace(scene.options, **changes)
    if "steps" in stepping:
        scene.dt = scene.t_end / stepping["steps"]
    elif scene.options.integration is not None and scene.dt is None:
        raise ValueError("an implicit run takes fixed steps: give --steps N (the steps to t_end)")
    return scene
