"""Build a system's SSP file: every component's FMU, the checks, SystemStructure.ssd, the zip.

:func:`build_system` reads a system file (docs/systems.md), builds each component's native
FMI 2.0 FMU (co-simulation and model exchange; the one place that calls the component builders
is :func:`component_fmu`), checks the connections and bindings against the FMUs'
modelDescription, writes SystemStructure.ssd, validates it against FMPy's shipped SSP 1.0
schema and replaces ``out`` atomically by the zip::

    SystemStructure.ssd
    resources/<Model>.fmu      one per distinct component FMU (two instances of one file share it)

The zip's bytes depend only on its content: entries in a fixed order, each dated 1980-01-01 and
with mode 0644, and each FMU re-packed the same way (its members in their order, dates fixed),
so the same system and the same FMUs give the same .ssp.
"""
from __future__ import annotations

import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from fourbar_common.files import replace_atomically

from .description import ComponentSpec, SystemDescription, SystemFileError, load_system
from .interface import FmuInterface, check_system, read_interface
from .ssd import resource_name, schema_problems, ssd_bytes

__all__ = ["ComponentFmu", "SystemBuildResult", "ComponentBuildError", "build_system", "component_fmu",
           "write_ssp", "SSD_NAME"]

#: The system structure description's name in the archive (SSP 1.0).
SSD_NAME = "SystemStructure.ssd"
_EPOCH = (1980, 1, 1, 0, 0, 0)
_MODE = 0o644 << 16


class ComponentBuildError(RuntimeError):
    """A component's FMU could not be built (its builder is missing, or compiling failed)."""


@dataclass(frozen=True)
class ComponentFmu:
    """A component instance and the FMU it runs: where it is in the .ssp, its model and GUID."""

    name: str
    kind: str
    source: str
    resource: str
    model_name: str
    guid: str


@dataclass(frozen=True)
class SystemBuildResult:
    path: Path
    name: str
    components: tuple[ComponentFmu, ...]
    problems: tuple[str, ...]            # what the SSP 1.0 schema found wrong: empty when valid


def component_fmu(spec: ComponentSpec, dest: Path, *, validate: bool = True) -> Path:
    """Build the native FMI 2.0 FMU of one component at ``dest``: a mechanism through
    fmu_src.native_build, a block through fmu_src.block_build (the block builder of issue 40).
    Raises SystemFileError (naming the component) for a mistake in its file,
    ComponentBuildError when it cannot be built."""
    where = f"components {spec.name!r}.{spec.kind} = {spec.source!r}"
    if spec.kind == "mechanism":
        from fmu_src.mechanism.description import MechanismError
        from fmu_src.native_build import CompilerNotFound, build_native_fmu
        try:
            result = build_native_fmu(dest, mechanism=spec.reference, validate=validate, fmi_version=2)
        except MechanismError as exc:
            raise SystemFileError(f"{where}: {exc}") from None
        except (CompilerNotFound, RuntimeError) as exc:
            raise ComponentBuildError(f"{where}: {exc}") from None
    else:
        try:
            from fmu_src.block_build import build_block_fmu
        except ImportError as exc:
            raise ComponentBuildError(f"{where}: block components need fmu_src.block_build, which this "
                                      f"checkout does not have ({exc})") from None
        try:
            build_block_fmu(spec.reference, dest, fmi_version=2)
        except ValueError as exc:       # the block file's own error (it names the file and item)
            raise SystemFileError(f"{where}: {exc}") from None
        except RuntimeError as exc:
            raise ComponentBuildError(f"{where}: {exc}") from None
        result = None
    if validate and result is None:
        from fmpy.validation import validate_fmu
        problems = validate_fmu(str(dest))
    else:
        problems = result.problems if result is not None else ()
    if problems:
        raise ComponentBuildError(f"{where}: fmpy validate: {'; '.join(problems)}")
    return dest


def _precheck(system: SystemDescription) -> None:
    """Refuse unknown shipped names before building anything (a build takes seconds)."""
    from fmu_src.mechanism.description import MechanismError, resolve_mechanism
    problems = []
    for spec in system.components:
        if spec.kind == "mechanism" and spec.source_path is None:
            try:
                resolve_mechanism(spec.source)
            except MechanismError as exc:
                problems.append(f"components {spec.name!r}.mechanism: {exc}")
    if problems:
        raise SystemFileError(f"{system.path}: " + ("\n  ".join([""] + problems) if len(problems) > 1
                                                     else problems[0]))


def _repacked(fmu: Path) -> bytes:
    """The FMU's zip re-written with fixed dates and modes (its members and their order kept)."""
    import io
    buffer = io.BytesIO()
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(buffer, "w") as dst:
        for info in src.infolist():
            fixed = zipfile.ZipInfo(info.filename, date_time=_EPOCH)
            fixed.external_attr = _MODE if not info.is_dir() else (0o755 << 16) | 0x10
            fixed.compress_type = info.compress_type
            dst.writestr(fixed, src.read(info), compress_type=info.compress_type)
    return buffer.getvalue()


def write_ssp(out: Path, ssd: bytes, resources: dict[str, Path]) -> None:
    """Replace ``out`` atomically by the zip of ``ssd`` and the FMUs ``resources`` (archive name
    -> built FMU), with deterministic bytes."""
    def write(tmp: Path) -> None:
        with zipfile.ZipFile(tmp, "w") as z:
            info = zipfile.ZipInfo(SSD_NAME, date_time=_EPOCH)
            info.external_attr = _MODE
            z.writestr(info, ssd, compress_type=zipfile.ZIP_DEFLATED)
            for name in sorted(resources):
                info = zipfile.ZipInfo(name, date_time=_EPOCH)
                info.external_attr = _MODE
                z.writestr(info, _repacked(resources[name]), compress_type=zipfile.ZIP_STORED)
    replace_atomically(out, write)


def build_system(source: str | Path, out: str | Path | None = None, *, validate: bool = True,
                 prebuilt: Mapping[str, Path] | None = None) -> SystemBuildResult:
    """Build the system file ``source`` (a name in systems/ or a path) into ``out`` (default
    build/<Name>.ssp).  ``prebuilt`` maps a component's file (its shipped name, or the resolved
    path of its file as a string: :attr:`ComponentSpec.reference`) to a native FMI 2.0 FMU the
    caller knows is current, used instead of building one (the tests share their builds so).
    Raises SystemFileError for a mistake in the system file or a component's
    file (nothing written), ComponentBuildError when a component cannot be built, OSError when
    ``out`` cannot be written (``out`` is then as it was)."""
    system = load_system(source)
    _precheck(system)
    out = Path(out) if out is not None else Path("build") / f"{system.name}.ssp"
    with tempfile.TemporaryDirectory(prefix="fourbar_system_") as tmp:
        stage = Path(tmp)
        built: dict[tuple[str, str], FmuInterface] = {}
        interfaces: dict[str, FmuInterface] = {}
        for index, spec in enumerate(system.components):
            key = (spec.kind, spec.reference)
            if key not in built:
                staged = stage / f"component{index}.fmu"
                if prebuilt is not None and spec.reference in prebuilt:
                    shutil.copyfile(prebuilt[spec.reference], staged)
                else:
                    component_fmu(spec, staged, validate=validate)
                interface = read_interface(staged)
                final = stage / "fmus" / f"{interface.model_name}.fmu"
                if final.exists():
                    raise SystemFileError(f"{system.path}: components {spec.name!r}: its FMU's model name "
                                          f"{interface.model_name!r} is another component file's too")
                final.parent.mkdir(exist_ok=True)
                shutil.move(staged, final)
                built[key] = read_interface(final)
            interfaces[spec.name] = built[key]
        check_system(system, interfaces)
        ssd = ssd_bytes(system, interfaces)
        problems = schema_problems(ssd) if validate else ()
        if problems:
            return SystemBuildResult(path=out, name=system.name, components=(), problems=problems)
        resources = {resource_name(i): i.path for i in built.values()}
        write_ssp(out, ssd, resources)
    components = tuple(ComponentFmu(name=s.name, kind=s.kind, source=s.source,
                                    resource=resource_name(interfaces[s.name]),
                                    model_name=interfaces[s.name].model_name, guid=interfaces[s.name].guid)
                       for s in system.components)
    return SystemBuildResult(path=out.resolve(), name=system.name, components=components, problems=())
