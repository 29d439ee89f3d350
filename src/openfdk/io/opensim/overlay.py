"""What an ``.osim`` cannot say — drivers, FDK DOFs, analysis settings — added by a
small YAML *overlay*, and the options of an import (``--ignore``, ``--geometry``).

Two ways to give them, one path through the loader:

* ``openfdk run model.osim trial.trc --with overlay.yaml --ignore Thelen2003Muscle``:
  the command line registers the options for that ``.osim`` (:func:`register`) before
  anything reads it;
* an overlay file that names its model, run as the model itself
  (``openfdk run overlay.yaml trial.trc``)::

      opensim: gait2392_simbody.osim     # relative to this file
      ignore: [Thelen2003Muscle, Mesh]   # element types left out (listed in summary.json)
      geometry: [../Geometry]            # more folders to look for meshes in
      ik_tasks: Setup_IK.xml             # OpenSim's IK marker weights and coordinate tasks
      drivers: {...}                     # any model-file section but the model's own
      fdk_dofs: {...}
      fdk: [knee_add_r, knee_tx_r]       # shorthand: these coordinates become FDK DOFs
                                         # (or fdk_dofs: [...] beside an fdk: {settings} section)
      lock: [arm_rot_r, pro_sup_r: 0.3]  # shorthand: hold coordinates (default value or given, rad/m)
      contact_regions: {knee_contact: {medial: {axis: [0, 0, -1]}, lateral: {axis: [0, 0, 1]}}}
      frames: {tibia_r: {tuberosity: [0.04, -0.09, 0.008]}}   # points in an OpenSim body's frame (m),
                                         # for measures (distance, vector, ...) of the overlay
      analysis: {marker_cutoff_hz: 6}
      external_loads: DM_ngait_og1_external_loads.xml   # OpenSim's ExternalLoads
      external_loads_cutoff_hz: 6        # low-pass of their samples, Hz (default: as given)

The overlay's sections are merged into the imported model mapping; a name the model
already defines is an error naming the overlay's entry. Overlay values are in SI units
(m, rad), the unit of the imported mapping. The ``.osim`` itself is never edited.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from ...model.errors import ModelError

#: overlay keys that are import options, not model-file sections
OPTION_KEYS = ("opensim", "ignore", "geometry", "ik_tasks")
#: model-file sections an overlay may not set (the .osim defines them)
MODEL_SECTIONS = ("bodies", "coordinates", "couplers", "units", "gravity", "name", "openfdk")


@dataclass
class ImportOptions:
    """``ignore``: element types to leave out; ``mesh_dirs``: more mesh folders;
    ``overlay``: path of an overlay YAML (or None); ``ik_tasks``: an OpenSim IK setup or
    tasks file (:mod:`.ik_tasks`), or None."""

    ignore: tuple = ()
    mesh_dirs: tuple = ()
    overlay: Path | None = None
    ik_tasks: Path | None = None
    external_loads: Path | None = None
    motion: Path | None = None
    motion_cutoff_hz: float | None = None
    actuators: Path | None = None
    external_loads_cutoff_hz: float | None = None
    joint_reaction: Path | None = None
    info: dict = field(default_factory=dict)


_REGISTERED: dict = {}


def _is_file(path):
    """Whether ``path`` is an existing regular file; False where the system cannot even
    look (a name too long, a NUL byte): the caller's message names the entry."""
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


def _is_dir(path):
    """Whether ``path`` is an existing folder (:func:`_is_file`'s caveat)."""
    try:
        return Path(path).is_dir()
    except (OSError, ValueError):
        return False


def _finite_number(v):
    """Whether the YAML value ``v`` is a finite number (not a bool; an integer beyond the
    float range is not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _key(path):
    import os

    return os.path.realpath(path)  # (Path.resolve raises on a symlink loop; the reader then says what is wrong)


def register(path, ignore=(), mesh_dirs=(), overlay=None, ik_tasks=None, external_loads=None, motion=None,
             motion_cutoff_hz=None, actuators=None, external_loads_cutoff_hz=None, joint_reaction=None):
    """Options for the ``.osim`` at ``path`` in this process (the command line's
    ``--ignore``, ``--geometry``, ``--with``, ``--ik-tasks``, ``--external-loads``,
    ``--external-loads-cutoff``, ``--joint-reaction`` …), or for the overlay file at
    ``path`` the same but ``overlay`` (``--with``): they replace the overlay's keys, and
    ``--ignore`` and ``--geometry`` add to its lists (:func:`overlay_model_data`)."""
    for d in mesh_dirs:
        if not _is_dir(d):
            raise ModelError(f"--geometry: folder {str(d)!r} does not exist")
    _REGISTERED[_key(path)] = ImportOptions(tuple(ignore), tuple(mesh_dirs), None if overlay is None else Path(overlay),
                                            None if ik_tasks is None else Path(ik_tasks),
                                            None if external_loads is None else Path(external_loads),
                                            None if motion is None else Path(motion), motion_cutoff_hz,
                                            None if actuators is None else Path(actuators),
                                            external_loads_cutoff_hz or None,
                                            None if joint_reaction is None else Path(joint_reaction))


def registered_options(path):
    """The ImportOptions registered for the ``.osim`` at ``path`` in this process (a copy
    without its import record), or None: what another process needs to import the model
    as this one does (:func:`register_options`; ``openfdk run --chunks`` sends it to the
    worker processes with the case)."""
    opts = _REGISTERED.get(_key(path))
    return None if opts is None else replace(opts, info={})


def register_options(path, options):
    """Register ``options`` (ImportOptions, from :func:`registered_options` in another
    process) for the ``.osim`` at ``path`` in this process."""
    _REGISTERED[_key(path)] = replace(options, info={})


_PATH_OPTIONS = ("overlay", "ik_tasks", "external_loads", "motion", "actuators", "joint_reaction")
_NUMBER_OPTIONS = ("motion_cutoff_hz", "external_loads_cutoff_hz")


def options_record(path):
    """The options the ``.osim`` at ``path`` was imported with in this process, as JSON
    for summary.json (``input.opensim_import.options``: files as absolute paths, only the
    options given), so that ``openfdk view``, ``plot`` and ``export-opensim`` read the
    model as the run did (:func:`register_record`); {} without any."""
    opts = _REGISTERED.get(_key(path))
    if opts is None:
        return {}
    out = {}
    if opts.ignore:
        out["ignore"] = list(opts.ignore)
    if opts.mesh_dirs:
        out["mesh_dirs"] = [str(Path(d).resolve()) for d in opts.mesh_dirs]
    for key in _PATH_OPTIONS:
        value = getattr(opts, key)
        if value is not None:
            out[key] = str(Path(value).resolve())
    for key in _NUMBER_OPTIONS:
        if getattr(opts, key):
            out[key] = float(getattr(opts, key))
    return out


def register_record(path, record):
    """Register for the ``.osim`` at ``path`` the options of a finished run's record
    (:func:`options_record`), unless options other than the defaults are registered for
    it in this process already (a caller's own choice stands). A record that is not a
    mapping of the known options is ignored: the model is then read without them."""
    current = _REGISTERED.get(_key(path))
    if current is not None and replace(current, info={}) != ImportOptions():
        return
    if not isinstance(record, dict) or not record or set(record) - {"ignore", "mesh_dirs", *_PATH_OPTIONS,
                                                                       *_NUMBER_OPTIONS}:
        return
    def texts(key):
        value = record.get(key, [])
        return tuple(value) if isinstance(value, list) and all(isinstance(v, str) for v in value) else ()
    paths = {k: Path(record[k]) if isinstance(record.get(k), str) else None for k in _PATH_OPTIONS}
    for key, value in paths.items():
        if value is not None and not _is_file(value):  # the run's files moved: read without them
            import warnings

            warnings.warn(f"{Path(path).name}: the run read it with {key.replace('_', ' ')} {str(value)!r}, which no "
                          "longer exists: the model is read without it", stacklevel=2)
            paths[key] = None
    numbers = {k: float(record[k]) if isinstance(record.get(k), (int, float)) and not isinstance(record.get(k), bool)
               else None for k in _NUMBER_OPTIONS}
    _REGISTERED[_key(path)] = ImportOptions(texts("ignore"), texts("mesh_dirs"), **paths, **numbers)


def import_info(path):
    """What the last import of ``path`` dropped and merged ({dropped, merged_bodies,
    motion_not_driven, …}), for summary.json; for an overlay file, that of the ``.osim``
    it names; {} if it was not an OpenSim import."""
    opts = _REGISTERED.get(_key(osim_of(path) or path))
    return {k: v for k, v in opts.info.items() if k not in ("body_frames", "offset_frames")} if opts else {}


def record_import(path, key, entries):
    """Add ``entries`` (a mapping) to the import record ``key`` of the model file ``path``
    (an ``.osim``, or an overlay naming one), read in this process; nothing otherwise."""
    opts = _REGISTERED.get(_key(osim_of(path) or path))
    if opts is not None:
        opts.info[key] = {**opts.info.get(key, {}), **entries}


def osim_of(path):
    """The ``.osim`` an overlay file ``path`` names (its ``opensim:`` key, relative to the
    overlay), or None for any other file (an ``.osim`` itself, a model file, one that
    cannot be read)."""
    from . import is_osim
    from ..yamlfile import read_yaml

    if is_osim(path) or Path(path).suffix.lower() not in (".yaml", ".yml"):
        return None
    try:
        data = read_yaml(path, ModelError, "model file")
    except ModelError:
        return None
    target = data.get("opensim") if isinstance(data, dict) else None
    return Path(path).parent / target if isinstance(target, str) and is_osim(target) else None


def _welds_to_keep(opts, extra=None):
    """The WeldJoints (names, or True for all) whose bodies the import keeps apart: the
    joints the run's JointReaction asks for (``--joint-reaction``, the ``--with``
    overlay's ``joint_reaction``, and ``extra``: (spec, folder) of an overlay run as the
    model), so that a weld among them has a load to report."""
    from ..yamlfile import read_yaml
    from .joint_reaction import requested_joints

    asked = []
    if opts.joint_reaction is not None:
        asked.append(requested_joints(str(opts.joint_reaction)))
    if opts.overlay is not None:
        try:
            overlay = read_yaml(opts.overlay, ModelError, "overlay file")
        except (ModelError, OSError):
            overlay = None  # read again below, which names the mistake
        if isinstance(overlay, dict) and "joint_reaction" in overlay:
            asked.append(requested_joints(overlay["joint_reaction"], Path(opts.overlay).parent))
    if extra is not None:
        asked.append(requested_joints(*extra))
    if any(a is True for a in asked):
        return True
    return tuple(n for a in asked for n in a)


def imported_model_data(path, extra_joint_reaction=None):
    """The model mapping of an ``.osim`` with its registered options, or None when
    ``path`` is not an ``.osim``; ``extra_joint_reaction``: (spec, folder) of the
    ``joint_reaction`` of an overlay run as the model (:func:`_welds_to_keep`)."""
    from . import is_osim, read_osim
    from ..yamlfile import read_yaml

    if not is_osim(path):
        return None
    opts = _REGISTERED.setdefault(_key(path), ImportOptions())
    data, info = read_osim(path, opts.ignore, opts.mesh_dirs, _welds_to_keep(opts, extra_joint_reaction))
    opts.info = info
    if opts.ik_tasks is not None:
        from .ik_tasks import apply_ik_tasks

        data = apply_ik_tasks(data, opts.ik_tasks, data.get("coordinates", {}), info["dropped"])
        info["ik_tasks"] = str(opts.ik_tasks)
    if opts.external_loads is not None:
        from .external_loads import read_external_loads

        data = read_external_loads(opts.external_loads, data, info, opts.external_loads_cutoff_hz)
        info["external_loads"] = str(opts.external_loads)
        if opts.external_loads_cutoff_hz:
            info["external_loads_cutoff_hz"] = float(opts.external_loads_cutoff_hz)
    if opts.actuators is not None:
        from .actuators import read_actuator_file

        data = read_actuator_file(opts.actuators, data, info)
        info["actuators"] = str(opts.actuators)
    if opts.joint_reaction is not None:
        from .joint_reaction import read_setup, resolved

        data = {**data, "joint_reaction": resolved(read_setup(opts.joint_reaction), data, info, Path(path).name)}
        info["joint_reaction"] = str(opts.joint_reaction)
    if opts.overlay is not None:
        overlay = read_yaml(opts.overlay, ModelError, "overlay file")
        data = merge_overlay(data, overlay, Path(opts.overlay).name, allow_options=False,
                             base_dir=Path(opts.overlay).parent, info=info)
    if opts.motion is not None:  # last, when the overlay's FDK DOFs and locks are known
        from .motion import motion_drivers

        if "motion" in info:
            raise ModelError(f"{Path(path).name}: --motion: the overlay {Path(opts.overlay).name} gives motion: "
                             f"{Path(info['motion']).name} too; give one of them")

        data = motion_drivers(opts.motion, data, opts.motion_cutoff_hz, info)
        info["motion"] = str(opts.motion)
    return data


def model_source(path):
    """How messages name the model file ``path``: its name, and for an ``.osim`` with a
    registered ``--with`` overlay both files (``leg.osim with with.yaml``), since the
    overlay's entries are read as entries of the model."""
    opts = _REGISTERED.get(_key(path))
    name = Path(path).name
    return f"{name} with {Path(opts.overlay).name}" if opts is not None and opts.overlay is not None else name


def overlay_model_data(path, data):
    """``data`` itself, or for an overlay file (an ``opensim:`` key) the imported model
    with the overlay merged in; the options registered for the overlay file itself (the
    command line's, e.g. ``openfdk run overlay.yaml og3.trc --external-loads og3.xml``
    or ``--motion ik.mot``: the two stages) replace its keys (:func:`_command_line_keys`)."""
    if not isinstance(data, dict) or "opensim" not in data:
        return data
    source = Path(path).name
    target = data["opensim"]
    from . import is_osim

    if not isinstance(target, str) or not is_osim(target):
        raise ModelError(f"{source}: opensim: expected the path of an .osim file, got {target!r}")
    osim = Path(path).parent / target
    for key in ("ignore", "geometry"):
        value = data.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise ModelError(f"{source}: {key}: expected a list of names, got {value!r}")
    for d in data.get("geometry", []):
        if not _is_dir(Path(path).parent / d):
            raise ModelError(f"{source}: geometry: folder {d!r} does not exist")
    data = _command_line_keys(data, _REGISTERED.get(_key(path)), source)
    tasks = data.get("ik_tasks")
    if tasks is not None and (not isinstance(tasks, str) or not _is_file(Path(path).parent / tasks)):
        raise ModelError(f"{source}: ik_tasks: expected the path of an existing IK setup or tasks file, got {tasks!r}")
    register(osim, data.get("ignore", []), [str(Path(path).parent / d) for d in data.get("geometry", [])],
             ik_tasks=None if tasks is None else Path(path).parent / tasks)
    if not _is_file(osim):
        raise ModelError(f"{source}: opensim: {target!r} does not exist")
    base = imported_model_data(osim, (data["joint_reaction"], Path(path).parent) if "joint_reaction" in data else None)
    info = _REGISTERED[_key(osim)].info
    return merge_overlay(base, data, source, allow_options=True, base_dir=Path(path).parent, info=info)


#: an overlay's keys that the command line's options (registered for the overlay file
#: itself, ImportOptions' attributes of the same names) replace: {key: the option's flag}
_REPLACED_KEYS = {"ik_tasks": "--ik-tasks", "external_loads": "--external-loads",
                  "external_loads_cutoff_hz": "--external-loads-cutoff", "motion": "--motion",
                  "motion_cutoff_hz": "--motion-cutoff", "actuators": "--actuators", "joint_reaction": "--joint-reaction"}


def _command_line_keys(data, own, source):
    """The overlay mapping ``data`` with the options given for the overlay file itself
    (``openfdk run dm_pt.yaml og3.trc --external-loads og3_loads.xml``: one overlay for
    every trial): each of :data:`_REPLACED_KEYS` given replaces the overlay's key (files
    as absolute paths), with a warning naming both when the overlay gives it too (an
    input check's: not given again when a finished run's model is read);
    ``--ignore`` and ``--geometry`` add to the overlay's lists."""
    if own is None:
        return data
    from ...model.plausibility import warn_plausibility

    out = dict(data)
    for key, flag in _REPLACED_KEYS.items():
        value = getattr(own, key)
        if value is None or value == 0:
            continue
        given = value if key.endswith("_hz") else str(Path(value).resolve())
        if key in out:
            old = out[key]
            old = Path(old).name if isinstance(old, str) else old if isinstance(old, (int, float)) else "its own"
            shown = value if key.endswith("_hz") else Path(value).name
            warn_plausibility(f"{source}: {key}: {old} replaced by {flag} {shown}")
        out[key] = given
    for key, flag, what in (("external_loads", "--external-loads-cutoff", "loads"),
                            ("motion", "--motion-cutoff", "coordinates")):
        if getattr(own, f"{key}_cutoff_hz") and key not in out:
            raise ModelError(f"{source}: {flag}: filters the {what} of {key.replace('_', ' ')}, which neither "
                             f"{flag.rsplit('-', 1)[0]} nor the overlay's {key}: gives")
    for key, values in (("ignore", list(own.ignore)), ("geometry", [str(Path(d).resolve()) for d in own.mesh_dirs])):
        if values:
            listed = out.get(key, [])
            out[key] = (listed + [v for v in values if v not in listed]) if isinstance(listed, list) else listed
    return out


def _coordinate_list(value, data, source, key):
    """[(name, value or None)] of an overlay list of coordinate names, each either a
    name or a one-entry mapping {name: value} (rad or m); errors name the entry."""
    coordinates = data.get("coordinates", {})
    if not isinstance(value, list):
        raise ModelError(f"{source}: {key}: expected a list of coordinate names, got {type(value).__name__}")
    out = []
    for k, item in enumerate(value):
        given = None
        if isinstance(item, dict) and len(item) == 1:
            (item, given), = item.items()
            if isinstance(given, bool) or not isinstance(given, (int, float)) or given != given or abs(given) == float("inf"):
                raise ModelError(f"{source}: {key}[{k}]: {item}: expected a finite number (rad or m), got {given!r}")
        if not isinstance(item, str) or item not in coordinates:
            hint = difflib.get_close_matches(str(item), list(coordinates), n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ModelError(f"{source}: {key}[{k}]: {item!r} is not a coordinate of the model{extra}")
        if item in [n for n, _ in out]:
            raise ModelError(f"{source}: {key}[{k}]: {item!r} is listed twice")
        out.append((item, given))
    return out


def _contact_regions(regions, data, source):
    """``data`` with ``contact_regions: {contact: {region: {axis, origin}}}`` set as the
    ``regions`` of the imported contacts (their entries are the .osim's, so an overlay
    cannot name them in ``contacts:``); the regions themselves are checked by the
    contacts section (contact/sections.py)."""
    if regions is None:
        return data
    contacts = data.get("contacts", {})
    if not isinstance(regions, dict):
        raise ModelError(f"{source}: contact_regions: expected a mapping of contact names, got "
                         f"{type(regions).__name__}")
    out = dict(contacts)
    for name, spec in regions.items():
        if name not in contacts:
            hint = difflib.get_close_matches(str(name), list(contacts), n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ModelError(f"{source}: contact_regions.{name}: not a contact of the model{extra} "
                             f"(contacts: {', '.join(contacts) or 'none'})")
        out[name] = {**contacts[name], "regions": spec}
    return {**data, "contacts": out}


def _overlay_frames(frames, data, source, info):
    """``data`` with ``frames: {osim_body: {name: [x, y, z] m}}`` added as frames of the
    openfdk bodies that hold those OpenSim bodies (a point given in the OpenSim body's frame,
    with its axes); measures name them ``<openfdk body>.<name>``. ``info['body_frames']``:
    each OpenSim body's frame in its openfdk body (:func:`.to_model.model_dict`)."""
    if frames is None:
        return data
    if not isinstance(frames, dict):
        raise ModelError(f"{source}: frames: expected a mapping of OpenSim body names, got {type(frames).__name__}")
    import numpy as np

    body_frames = info.get("body_frames", {})
    bodies = {k: dict(v) for k, v in data.get("bodies", {}).items()}
    for osim_body, points in frames.items():
        if osim_body not in body_frames:
            hint = difflib.get_close_matches(str(osim_body), list(body_frames), n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ModelError(f"{source}: frames.{osim_body}: not a body of the OpenSim model{extra}")
        if not isinstance(points, dict):
            raise ModelError(f"{source}: frames.{osim_body}: expected a mapping of frame names to [x, y, z] (m)")
        body, p, R = body_frames[osim_body]
        entry = bodies.setdefault(body, {})
        own = dict(entry.get("frames", {}))
        for name, xyz in points.items():
            ok = isinstance(xyz, list) and len(xyz) == 3 and all(_finite_number(v) for v in xyz)
            if not ok:
                raise ModelError(f"{source}: frames.{osim_body}.{name}: expected [x, y, z] in m, got {xyz!r}")
            if name in own:
                raise ModelError(f"{source}: frames.{osim_body}.{name}: the body {body!r} already has a frame "
                                 f"{name!r}")
            own[name] = {"position": (np.asarray(p, float) + np.asarray(R, float) @ np.asarray(xyz, float)).tolist(),
                         "orientation": {"matrix": np.asarray(R, float).tolist()}}
        entry["frames"] = own
    return {**data, "bodies": bodies}


def _expand_shorthands(overlay, data, source):
    """``fdk: [names]`` (a list; a mapping is the FDK settings section) → ``fdk_dofs``
    entries {measure: name, initial: the coordinate's default}; ``lock: [names]`` → ``constraints`` entries ``lock_<name>`` {measure: name,
    value: given or default}. A coordinate both locked and FDK is an error."""
    overlay = dict(overlay)
    coordinates = data.get("coordinates", {})
    # ``fdk:`` as a list names coordinates; as a mapping it is the solver's settings section,
    # and the list can then be given as ``fdk_dofs: [names]``
    fdk = _coordinate_list(overlay.pop("fdk"), data, source, "fdk") if isinstance(overlay.get("fdk"), list) else []
    if isinstance(overlay.get("fdk_dofs"), list):
        if fdk:
            raise ModelError(f"{source}: fdk_dofs: give the FDK coordinates once (fdk: [...] or fdk_dofs: [...])")
        fdk = _coordinate_list(overlay.pop("fdk_dofs"), data, source, "fdk_dofs")
    lock = _coordinate_list(overlay.pop("lock"), data, source, "lock") if "lock" in overlay else []
    both = sorted({n for n, _ in fdk} & {n for n, _ in lock})
    if both:
        raise ModelError(f"{source}: lock: {both[0]!r} is also listed under fdk (a coordinate is either held or "
                         "force-dependent)")
    for key, section, entries in (
        ("fdk", "fdk_dofs", {n: {"measure": n, "initial": float(coordinates[n].get("default", 0.0) if v is None else v)}
                             for n, v in fdk}),
        ("lock", "constraints", {f"lock_{n}": {"measure": n, "value": float(coordinates[n].get("default", 0.0)
                                                                           if v is None else v)}
                                 for n, v in lock})):
        if not entries:
            continue
        own = overlay.get(section, {})
        if not isinstance(own, dict):
            raise ModelError(f"{source}: {section}: expected a mapping, got {type(own).__name__}")
        clash = sorted(set(own) & set(entries))
        if clash:
            raise ModelError(f"{source}: {section}.{clash[0]}: also made by the {key} list")
        overlay[section] = {**own, **entries}
    return overlay


def _named(source, key, read, *args):
    """``read(*args)``, its one-line error (ModelError) prefixed with the overlay file and
    the key that named the file read (``dm.yaml: external_loads: passwd: not well-formed
    XML …``): the file's own message names the file but not where it was given. A
    message that names the command-line option (``--motion: …``) names the key instead."""
    try:
        return read(*args)
    except ModelError as exc:
        message = str(exc)
        for flag in ("--motion: ", "--external-loads: ", "--actuators: ", "--joint-reaction: "):
            message = message.removeprefix(flag)
        raise type(exc)(f"{source}: {key}: {message}") from None


def merge_overlay(data, overlay, source, allow_options, base_dir=None, info=None):
    """The imported mapping ``data`` with the sections of ``overlay`` added (module
    docstring); errors name the overlay file and the entry. ``external_loads: FILE.xml``
    (OpenSim's ExternalLoads), ``motion: FILE.mot``, ``motion_cutoff_hz`` and
    ``actuators: FILE.xml`` (an OpenSim actuator file) are read relative to ``base_dir``
    (the overlay's folder)."""
    from ...model.modelfile import CORE_SECTIONS
    from ..modelfile import SECTIONS

    if not isinstance(overlay, dict):
        raise ModelError(f"{source}: an overlay must be a mapping of model-file sections")
    overlay = dict(overlay)
    base_dir = Path(base_dir or ".")
    info = {} if info is None else info
    loads_cutoff = overlay.pop("external_loads_cutoff_hz", None)
    if loads_cutoff is not None and (isinstance(loads_cutoff, bool) or not isinstance(loads_cutoff, (int, float))
                                     or not loads_cutoff >= 0):
        raise ModelError(f"{source}: external_loads_cutoff_hz: expected a number >= 0 (Hz), got {loads_cutoff!r}")
    if isinstance(overlay.get("external_loads"), str):
        from .external_loads import read_external_loads

        xml = base_dir / overlay.pop("external_loads")
        if not _is_file(xml):
            raise ModelError(f"{source}: external_loads: {str(xml)!r} does not exist")
        data = _named(source, "external_loads", read_external_loads, xml, data, info, loads_cutoff)
    elif loads_cutoff:
        # the loads of --external-loads (read before the overlay): the same low-pass
        if not data.get("external_loads"):
            raise ModelError(f"{source}: external_loads_cutoff_hz: no external loads to filter (give external_loads: "
                             "FILE.xml here or --external-loads)")
        data = dict(data)
        data["external_loads"] = {name: {"cutoff_hz": float(loads_cutoff), **entry}
                                  for name, entry in data["external_loads"].items()}
    if loads_cutoff:
        info["external_loads_cutoff_hz"] = float(loads_cutoff)
    cutoff = overlay.pop("motion_cutoff_hz", None)
    if cutoff is not None and (isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not cutoff > 0):
        raise ModelError(f"{source}: motion_cutoff_hz: expected a positive number (Hz), got {cutoff!r}")
    given_motion = "motion" in overlay
    motion = overlay.pop("motion", None)  # read last, when the FDK DOFs and locks are known
    if given_motion and (not isinstance(motion, str) or not _is_file(base_dir / motion)):
        raise ModelError(f"{source}: motion: expected an existing .mot/.sto file, got {motion!r}")
    if cutoff and motion is None:
        raise ModelError(f"{source}: motion_cutoff_hz: filters the coordinates of a motion file, and none is given "
                         "(motion: FILE.mot here or --motion)")
    if isinstance(overlay.get("actuators"), str):
        from .actuators import read_actuator_file

        xml = base_dir / overlay.pop("actuators")
        if not _is_file(xml):
            raise ModelError(f"{source}: actuators: {str(xml)!r} does not exist")
        data = _named(source, "actuators", read_actuator_file, xml, data, info)
    data = _overlay_frames(overlay.pop("frames", None), data, source, info)
    if "joint_reaction" in overlay:
        from .joint_reaction import read_setup, resolved

        if "joint_reaction" in data:
            raise ModelError(f"{source}: joint_reaction: given by --joint-reaction too; give one of them")

        spec = overlay["joint_reaction"]
        if isinstance(spec, str):
            xml = base_dir / spec
            if not _is_file(xml):
                raise ModelError(f"{source}: joint_reaction: {str(xml)!r} does not exist")
            spec = _named(source, "joint_reaction", read_setup, xml)
        overlay["joint_reaction"] = resolved(spec, data, info, source)
    overlay = _expand_shorthands(overlay, data, source)
    data = _contact_regions(overlay.pop("contact_regions", None), data, source)
    known = [k for k in CORE_SECTIONS + tuple(name for name, _ in SECTIONS) if k not in MODEL_SECTIONS]
    out = dict(data)
    for key, value in overlay.items():
        if key not in known + list(OPTION_KEYS) + list(MODEL_SECTIONS):
            hint = difflib.get_close_matches(str(key), known + list(OPTION_KEYS), n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ModelError(f"{source}: {key}: not a model-file section an overlay can add{extra} (sections: "
                             f"{', '.join(known)})")
        if key not in OPTION_KEYS + MODEL_SECTIONS + ("description",) and not isinstance(value, dict):
            raise ModelError(f"{source}: {key}: expected a mapping, got {type(value).__name__}")
        if key in OPTION_KEYS:
            if not allow_options:
                raise ModelError(f"{source}: {key}: give it on the command line (--ignore, --geometry) or run the "
                                 "overlay itself as the model")
            continue
        if key in MODEL_SECTIONS:
            raise ModelError(f"{source}: {key}: an overlay cannot change the OpenSim model's {key} "
                             "(overlay values are in SI units: m, rad)")
        if key not in out:
            out[key] = value
            continue
        if not isinstance(value, dict) or not isinstance(out[key], dict):
            raise ModelError(f"{source}: {key}: expected a mapping")
        merged = dict(out[key])
        for name, entry in value.items():
            if name in merged:
                raise ModelError(f"{source}: {key}.{name}: already defined by the OpenSim model")
            merged[name] = entry
        out[key] = merged
    if motion is not None:
        from .motion import motion_drivers

        out = _named(source, "motion", motion_drivers, base_dir / motion, out, cutoff, info)
        info["motion"] = str(base_dir / motion)
    return out
