"""A scene from TOML text or a file: every table read into its dataclass, then the rules that tie
tables together (a [hammer] needs the reduced apparatus, [fep] needs [nnm], ...), each refusal one
line naming the file, table and key. Built-in scenes are the ``*.toml`` files of this package."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from bearingshaft.scenes.convert import from_table
from bearingshaft.scenes.errors import SceneError, show, suggest
from bearingshaft.scenes.loads import parse_loads
from bearingshaft.scenes.models import MODEL_KINDS, model_class
from bearingshaft.scenes.scene import Scene
from bearingshaft.scenes.sweep import parse_sweep_table
from bearingshaft.scenes.tables import SECTIONS, InitialSpec


def parse_scene(text: str, default_name: str, origin: str, base: str | Path | None = None) -> Scene:
    """A :class:`Scene` from TOML text.

    Parameters
    ----------
    text : str
        The scene's TOML.
    default_name : str
        Its name when the text gives none (the file's stem).
    origin : str
        Where the text comes from, named at the start of every error message.
    base : str or Path, optional
        The folder the scene's file paths are relative to (its file's folder; None: the working directory).

    Returns
    -------
    Scene
        Every table read into its dataclass and checked against the others.

    Raises
    ------
    SceneError
        One line naming the file, table and key, at the first thing wrong.
    """
    data = _read_toml(text, origin)
    name, description = _name_and_description(data, default_name, origin)
    kind, model = _read_model(data, origin, base)
    sections = {
        key: from_table(cls, data[key], f"{origin} [{key}]", base) for key, cls in SECTIONS.items() if key in data
    }
    if "sweep" in data:  # the table only: its cases are built and checked by bearingshaft.sweep
        sections["sweep"] = parse_sweep_table(data["sweep"], origin)
    if not hasattr(model, "system"):  # a 3-D model: only [modal] applies
        other = [k for k in sections if k not in ("modal", "sweep")] + (["[load]"] if "load" in data else [])
        if other:
            raise SceneError(f"{origin}: model kind {kind!r} takes only a [modal] table, got [{other[0]}]")
        return Scene(name=name, description=description, model_kind=kind, model=model, source=text, origin=origin,
                     folder=_folder(base), **sections)
    _check_tables_of_kind(sections, kind, origin)
    dof_names = _check_points(sections, kind, model, origin, "load" in data)
    if "frf" in sections and "hammer" not in sections:  # the FRFs of the rig's hammer test
        raise SceneError(f"{origin} [frf]: needs a [hammer] table (the rig, its channels and record)")
    if "identify" in sections and "hammer" not in sections:  # fitted to a hammer test on the rig
        raise SceneError(f"{origin} [identify]: needs a [hammer] table (the rig, its channels and record)")
    loads, signals = _read_loads(data, sections, dof_names, origin, base)
    if "fep" in sections and "nnm" not in sections:
        raise SceneError(f"{origin}: [fep] needs an [nnm] table (its energy range and grid)")
    if "frc" in sections:
        _check_frc(sections["frc"], kind, model, dof_names, origin)
    if ("spectrogram" in sections or "symmetry" in sections) and "ringdown" not in sections:
        raise SceneError(f"{origin}: [spectrogram] and [symmetry] need a [ringdown] table")
    return Scene(name=name, description=description, model_kind=kind, model=model, source=text, origin=origin,
                 folder=_folder(base), loads=loads, load_signals=signals, **sections)


def _folder(base: str | Path | None) -> str:
    return str(Path(base if base is not None else ".").absolute())


def _read_toml(text: str, origin: str) -> dict:
    """The TOML data, its top-level keys known."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: invalid TOML: {exc}") from None
    top = {"name", "description", "model", "load", "sweep", *SECTIONS}
    for key in data:
        if key not in top:
            raise SceneError(f"{origin}: unknown key {key!r}{suggest(key, top)} (known: {', '.join(sorted(top))})")
    return data


def _name_and_description(data: dict, default_name: str, origin: str) -> tuple[str, str]:
    name = data.get("name", default_name)
    description = data.get("description", "")
    if not isinstance(name, str) or not name or "/" in name or name.startswith(".") or len(name) > 200:
        raise SceneError(f"{origin}: name must be a non-empty string without '/' or a leading '.', "
                         f"got {show(name)}")
    if not isinstance(description, str):
        raise SceneError(f"{origin}: description must be a string, got {show(description)}")
    return name, description


def _read_model(data: dict, origin: str, base: str | Path | None = None) -> tuple[str, object]:
    """(kind, model) of the [model] table (kind "discrete" when not given, and the message says so)."""
    model_table = data.get("model", {})
    if not isinstance(model_table, dict):
        raise SceneError(f"{origin} [model]: expected a table, got {show(model_table)}")
    model_table = dict(model_table)
    kind = model_table.pop("kind", "discrete")
    if not isinstance(kind, str):
        raise SceneError(f"{origin} [model] kind: expected a string (one of {', '.join(MODEL_KINDS)}), "
                         f"got {show(kind)}")
    if kind not in MODEL_KINDS:
        raise SceneError(f"{origin} [model] kind: unknown model {show(kind)}{suggest(kind, MODEL_KINDS)} "
                         f"(known: {', '.join(MODEL_KINDS)})")
    try:
        return kind, from_table(model_class(kind), model_table, f"{origin} [model]", base)
    except SceneError as exc:
        if "kind" in data.get("model", {}):
            raise
        raise SceneError(f"{exc}; [model] kind is not given, so {kind!r} is assumed") from None


def _check_tables_of_kind(sections: dict, kind: str, origin: str) -> None:
    """Tables that need a 3-D, a discrete or a reduced model are refused on the others."""
    if "modal" in sections:
        raise SceneError(f"{origin}: [modal] needs a 3-D model (kind = \"assembly\"), not {kind!r}")
    if kind == "rom":
        for key in ("work_precision",):  # [nnm] and [fep] run on a reduced model too (stages/nnm_fep.py)
            if key in sections:
                raise SceneError(f"{origin}: [{key}] is for the discrete model; a reduced model has "
                                 "[ringdown], [nnm], [fep], [stiff_cases], [rom_convergence] and [verify]")
    else:
        for key in ("rom_convergence", "verify"):
            if key in sections:
                raise SceneError(f"{origin}: [{key}] needs a reduced model (kind = \"rom\"), not {kind!r}")
    if kind == "discrete_friction":  # the studies and the NNMs do not treat friction yet; [frc] does (HB by AFT)
        for key in ("nnm", "fep", "work_precision", "stiff_cases", "symmetry"):
            if key in sections:
                raise SceneError(f"{origin}: [{key}] does not treat friction; the model with friction "
                                 "(kind = \"discrete_friction\") has [ringdown], [spectrogram] and [frc]")


def _check_points(sections: dict, kind: str, model, origin: str, has_loads: bool) -> tuple[str, ...]:
    """The names [initial], [spectrogram] and [symmetry] refer to, checked: the model's points, or with
    [hammer] the rig's channels."""
    dof_names = model.point_names
    n = len(dof_names)
    init = sections.get("initial", InitialSpec())
    for key in ("x0_m", "v0_m_s"):
        if len(getattr(init, key)) != n:
            raise SceneError(f"{origin} [initial] {key}: needs {n} values ({', '.join(dof_names)}), "
                             f"got {len(getattr(init, key))}")
    if sections.get("hammer") is not None:
        _check_hammer(sections, kind, model, origin, has_loads)
        from fem.rig import channel_names

        dof_names = channel_names()  # [spectrogram] dof names a channel of the rig
    spec = sections.get("spectrogram")
    if spec is not None and spec.dof not in dof_names:
        raise SceneError(f"{origin} [spectrogram] dof: unknown DOF {spec.dof!r} (known: {', '.join(dof_names)})")
    sym = sections.get("symmetry")
    if sym is not None and any(d not in dof_names for d in sym.dofs):
        raise SceneError(f"{origin} [symmetry] dofs: unknown DOF in {sym.dofs!r}")
    if spec is not None and "ringdown" in sections and spec.window_s > sections["ringdown"].duration_s:
        raise SceneError(f"{origin} [spectrogram] window_s: {spec.window_s!r} s is longer than the run "
                         f"([ringdown] duration_s = {sections['ringdown'].duration_s!r} s)")
    return dof_names


def _read_loads(data: dict, sections: dict, dof_names, origin: str, base: str | Path | None = None
                ) -> tuple[tuple, tuple]:
    """([[load]] specs, their signals): loads drive a [ringdown] within its duration, and no free study."""
    if "load" not in data:
        return (), ()
    loads, signals = parse_loads(data["load"], origin, dof_names, base)
    if "ringdown" not in sections:
        raise SceneError(f"{origin} [[load]]: loads drive the ringdown stage; add a [ringdown] table")
    for key in ("work_precision", "stiff_cases", "rom_convergence", "verify"):
        if key in sections:
            raise SceneError(f"{origin} [[load]]: [{key}] runs free ringdowns; put the loads in a scene "
                             "without it")
    duration = sections["ringdown"].duration_s
    for i, sig in enumerate(signals):
        if sig.start_s >= duration:
            raise SceneError(f"{origin} [[load]] {i + 1} start_s: the load starts at {sig.start_s!r} s, "
                             f"at or after the end of the run ([ringdown] duration_s = {duration!r} s)")
    return loads, signals


def _check_frc(frc, kind: str, model, dof_names, origin: str) -> None:
    """[frc] loads a point of the model, which needs damping for a forced response to settle."""
    for key, point in (("point", frc.point), *(("also_points", p) for p in frc.also_points)):
        if point not in dof_names:
            raise SceneError(f"{origin} [frc] {key}: unknown point {point!r}{suggest(point, dof_names)} "
                             f"(known: {', '.join(dof_names)})")
    discrete = kind in ("discrete", "discrete_friction")
    damping = (model.c,) if discrete else (model.c_points, model.alpha, *model.modal_damping)
    if not any(d > 0 for d in damping):
        raise SceneError(f"{origin} [frc]: the model has no damping ([model] "
                         f"{'c' if discrete else 'c_points, alpha or modal_damping'} = 0), so no forced "
                         "response settles and the curves have no peak; give the model damping")


def _check_hammer(sections: dict, kind: str, model, origin: str, has_loads: bool) -> None:
    """[hammer] needs a reduced model of the whole assembly, a [ringdown] and no other load or stage."""
    if kind != "rom" or model.layout != "assembly":
        raise SceneError(f"{origin} [hammer]: the virtual test needs the reduced apparatus ([model] kind = \"rom\", "
                         "layout = \"assembly\")")
    if "ringdown" not in sections:
        raise SceneError(f"{origin} [hammer]: add a [ringdown] table (the record's duration_s, sample_rate_hz, "
                         "method)")
    if has_loads:
        raise SceneError(f"{origin} [[load]]: [hammer] is the load of a virtual test; drop [[load]] or [hammer]")
    for key in ("symmetry", "work_precision", "stiff_cases", "rom_convergence", "verify", "frc"):
        if key in sections:
            raise SceneError(f"{origin}: [{key}] does not go with [hammer]; put it in another scene")
    h, rd = sections["hammer"], sections["ringdown"]
    if h.start_s + h.duration_s > rd.duration_s:
        raise SceneError(f"{origin} [hammer] start_s: the blow ends at {h.start_s + h.duration_s!r} s, after the "
                         f"record ([ringdown] duration_s = {rd.duration_s!r} s)")
    from fem.rig import channel_names

    names = channel_names()
    for c in h.compare:
        if c not in names:
            raise SceneError(f"{origin} [hammer] compare: unknown channel {c!r}{suggest(c, names)}")


# -- built-in scenes ---------------------------------------------------------------------
def builtin_names() -> list[str]:
    """Names of the scenes shipped with the package, sorted."""
    folder = resources.files("bearingshaft") / "scenes"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scene(name_or_path: str) -> Scene:
    """A built-in scene by name, or a scene from a TOML file path.

    Parameters
    ----------
    name_or_path : str
        A path ending in .toml or that exists, else the name of a built-in scene.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        An unreadable file, not UTF-8 text, an unknown name (with the nearest one), or a scene
        :func:`parse_scene` refuses.
    """
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise SceneError(f"{name_or_path}: cannot read scene file ({exc.strerror})") from None
        except UnicodeDecodeError:
            raise SceneError(f"{name_or_path}: not a text file (a scene is TOML in UTF-8)") from None
        return parse_scene(text, path.stem, str(path), path.absolute().parent)
    if name_or_path not in builtin_names():
        hint = suggest(name_or_path, builtin_names())
        raise SceneError(
            f"unknown scene {name_or_path!r}{hint}: not a file, and no built-in scene has that name"
            + ("" if hint else f" (built-in: {', '.join(builtin_names())})")
        )
    folder = resources.files("bearingshaft") / "scenes"
    text = (folder / f"{name_or_path}.toml").read_text(encoding="utf-8")
    return parse_scene(text, name_or_path, f"scene {name_or_path}", Path(str(folder)))

