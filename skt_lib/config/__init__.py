"""Typed, validated parameters (``params.yaml``), one module per stage's section.

Each section of ``params.yaml`` has its pydantic model in ``skt_lib/config/<section>.py``;
this module holds what every stage shares (the ``common`` and ``compute`` sections, the
level and category names, the section base) and :func:`load_sections`, which reads and
validates only the sections a stage names. A stage imports only its own sections' modules,
so DVC (whose deps are the modules a stage imports, ``tools/stage_deps.py``) reruns only
that stage and its downstream when one section's code or help strings change. A field that
an upstream stage reads from a later section (``clustering.T`` in ``rrt_skts``, the object
damping of ``sim_eval`` in ``contact_sim``, ``sim_eval.n_proposals`` in
``train_baselines``) is defined in a module of its own that both import.
:mod:`skt_lib.config.params_file` validates the whole file at once (tools, the CLI, tests).

Unknown keys, missing keys, wrong types and out-of-range values fail at load time with a
:class:`~skt_lib.errors.ParamsError` whose message names the offending key, e.g.
``mesh_gen.n_supports``. All lengths are metres.
"""

from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from skt_lib.errors import ParamsError

LEVELS = ("easy", "normal", "hard", "very_hard")
OBJECT_CATEGORIES = ("mug", "cooking_utensil", "scissor", "tool", "other")

PositiveLength = Annotated[float, Field(gt=0.0, le=1.0)]


class Section(BaseModel):
    """A params.yaml section: every key known, none missing, values frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class Partial(BaseModel):
    """Some fields of a later stage's section, read by an earlier stage (its other keys are
    that stage's own business and are left alone)."""

    model_config = ConfigDict(extra="ignore", frozen=True, strict=False)


def check_range(name: str, rng: tuple[float, float]) -> None:
    if rng[0] > rng[1]:
        raise ValueError(f"{name}: lower bound {rng[0]} is above upper bound {rng[1]}")


class CommonParams(Section):
    seed: int = Field(ge=0, description="The one seed every generator is derived from.")


class ComputeParams(Section):
    backend: Literal["local", "dask"] = Field(
        description="Per-item executor: local processes, or a Dask distributed cluster."
    )
    n_workers: int = Field(ge=1, le=256, description="Worker processes (local or LocalCluster).")
    scheduler_address: str | None = Field(
        default=None, description="Dask scheduler 'tcp://host:port'; null starts a LocalCluster."
    )


def format_error(source: str, err: ValidationError, prefix: str = "") -> str:
    """One line per error, each naming ``source`` and the key (``prefix`` + its location)."""
    lines = []
    for e in err.errors():
        key = prefix + ".".join(str(p) for p in e["loc"]) or "<root>"
        msg = e["msg"].removeprefix("Value error, ")
        got = f" (got {e['input']!r})" if e["type"] != "missing" and "input" in e else ""
        if e["type"] == "extra_forbidden":
            msg = "unknown key (misspelt?)"
            got = ""
        lines.append(f"{source}: {key.rstrip('.') or '<root>'}: {msg}{got}")
    return "\n".join(lines)


def read_params(path: str | Path) -> dict:
    """``params.yaml`` as a mapping of sections (not validated yet)."""
    path = Path(path)
    if not path.is_file():
        raise ParamsError(f"{path}: params file not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ParamsError(f"{path}: not valid YAML: {err}") from None
    if not isinstance(data, dict):
        raise ParamsError(f"{path}: expected a mapping of sections, got {type(data).__name__}")
    return data


class Sections:
    """The validated sections a stage asked for, as attributes (``params.rrt_skts``)."""

    def __init__(self, sections: dict[str, BaseModel]):
        self.__dict__.update(sections)

    def __setattr__(self, name, value):
        raise AttributeError(f"params are read-only ({name})")


def parse_sections(data: dict, source: str = "params", **models: type[BaseModel]) -> Sections:
    """The ``models`` (section name → model) of ``data``, each validated; a
    :class:`ParamsError` naming every bad key of them (other sections are not looked at)."""
    out, errors = {}, []
    for name, model in models.items():
        if name not in data:
            errors.append(f"{source}: {name}: missing section")
            continue
        try:
            out[name] = model.model_validate(data[name])
        except ValidationError as err:
            errors.append(format_error(source, err, f"{name}."))
    if errors:
        raise ParamsError("\n".join(errors))
    return Sections(out)


def load_sections(path: str | Path, **models: type[BaseModel]) -> Sections:
    """Read ``path`` and validate the sections a stage reads (:func:`parse_sections`), e.g.
    ``load_sections("params.yaml", common=CommonParams, rrt_skts=RrtSktsParams)``."""
    return parse_sections(read_params(path), str(path), **models)
