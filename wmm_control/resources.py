"""The files a URDF names (meshes), found the one way every reader of the URDF uses.

A URDF names its meshes as ``package://PKG/path``, ``file:///absolute/path``, an absolute path,
or a path relative to the URDF's folder. Every reader of those files resolves them here:
pinocchio's collision and workspace models and the viewer (:func:`load_geometry`), and
PyBullet, the simulator (:func:`loadable_urdf`). So they all read the same file, and a
description whose file cannot be found fails once, before anything is loaded, with one line
that names the file and what to set (:func:`check_resources`, which
:func:`~wmm_control.robot_config.load_robot` runs and so every node at start and
``wmm_robot check``).

``package://PKG/path`` is ``DIR/PKG/path`` for the first folder ``DIR`` (or ``DIR/path`` when
``DIR`` is itself named ``PKG``) of, in this order:

1. ``package_dirs`` of the robot YAML (relative to the YAML; ``wmm_robot init --package-dir``
   writes them);
2. each entry of ``ROS_PACKAGE_PATH``;
3. the ``share`` folder of each entry of ``AMENT_PREFIX_PATH`` (a sourced ROS 2 install).

Nothing else is searched: a package installed some other way (a Python wheel that ships
robot descriptions, for one) is found once its folder is named in ``package_dirs`` or
``ROS_PACKAGE_PATH``.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from pathlib import Path
from urllib.parse import unquote, urlparse

from wmm_control.errors import ConfigError

__all__ = [
    'search_dirs',
    'resolve_resource',
    'check_resources',
    'resolved_urdf_text',
    'loadable_urdf',
    'load_geometry',
    'yaml_package_dirs',
]

_PACKAGE = 'package://'
_FILE = 'file://'
#: How to make a package known, the end of every "not found" message.
_WHAT_TO_SET = (
    'set package_dirs in the robot YAML (wmm_robot init --package-dir DIR) or ROS_PACKAGE_PATH '
    'to the folder that holds {pkg}/'
)


def search_dirs(package_dirs: Iterable[str | Path] = ()) -> list[Path]:
    """The folders ``package://`` URIs are looked up in, in the order of the module docstring."""
    out = [Path(d) for d in package_dirs]
    out += [Path(d) for d in os.environ.get('ROS_PACKAGE_PATH', '').split(os.pathsep) if d]
    out += [Path(d) / 'share' for d in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if d]
    return out


def yaml_package_dirs(raw, yaml_path: Path) -> tuple[Path, ...]:
    """The ``package_dirs`` entry of a robot YAML's mapping ``raw``, each folder made absolute
    against the YAML's folder (none when the key is absent).

    Raises:
        ConfigError: not a list of folder names, or a folder that does not exist.
    """
    value = raw.get('package_dirs')
    if value is None:
        return ()
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ConfigError(f'package_dirs: expected a list of folders (relative to this file), got {value!r}')
    dirs = tuple((yaml_path.parent / Path(v).expanduser()).resolve() for v in value)
    missing = [str(d) for d in dirs if not d.is_dir()]
    if missing:
        raise ConfigError(f'package_dirs: folder not found: {missing[0]}')
    return dirs


def resolve_resource(uri: str, urdf_dir: Path, search: Sequence[Path], where: str = '') -> Path:
    """The file ``uri`` (a URDF ``filename``) names, as an absolute path.

    Args:
        uri: ``package://PKG/path``, ``file://...``, an absolute or a relative path.
        urdf_dir: the folder relative paths start from (the URDF's).
        search: :func:`search_dirs`.
        where: the URDF's name, to start the error message with.

    Raises:
        ConfigError: the package is in none of the folders, or the file does not exist (one
            line naming the file and what to set).
    """
    prefix = f'{where}: ' if where else ''
    if uri.startswith(_PACKAGE):
        pkg, _, rest = uri[len(_PACKAGE) :].partition('/')
        roots = [d / pkg for d in search if (d / pkg).is_dir()]
        roots += [d for d in search if d.name == pkg and d.is_dir()]
        if not roots:
            searched = ', '.join(str(d) for d in search) or 'nothing: none is set'
            raise ConfigError(
                f'{prefix}package {pkg!r} of {uri} not found (searched {searched}): ' + _WHAT_TO_SET.format(pkg=pkg)
            )
        for root in roots:
            if (root / rest).is_file():
                return (root / rest).resolve()
        raise ConfigError(f'{prefix}file missing: {roots[0] / rest} ({uri}; package {pkg!r} is {roots[0]})')
    if uri.startswith(_FILE):
        path = Path(unquote(urlparse(uri).path))
    else:
        path = Path(uri).expanduser()
        if not path.is_absolute():
            path = urdf_dir / path
    if not path.is_file():
        raise ConfigError(f'{prefix}file missing: {path} ({uri})')
    return path.resolve()


def _mesh_elements(root: ET.Element) -> list[ET.Element]:
    return [mesh for mesh in root.iter('mesh') if mesh.get('filename')]


def _parse(urdf_path: Path) -> ET.Element:
    try:
        return ET.parse(urdf_path).getroot()
    except OSError as exc:
        raise ConfigError(f'{urdf_path}: URDF unreadable: {exc.strerror or exc}') from exc
    except ET.ParseError as exc:
        raise ConfigError(f'{urdf_path}: URDF unreadable: not valid XML ({exc})') from exc


def check_resources(urdf_path: str | Path, package_dirs: Iterable[str | Path] = ()) -> int:
    """Resolve every mesh the URDF names (visual and collision); returns how many it names.

    Raises:
        ConfigError: the first one that cannot be found (:func:`resolve_resource`).
    """
    return len(_resolved(Path(urdf_path), package_dirs)[1])


def _resolved(urdf_path: Path, package_dirs) -> tuple[ET.Element, list[tuple[ET.Element, Path]]]:
    root = _parse(urdf_path)
    search = search_dirs(package_dirs)
    meshes = [
        (mesh, resolve_resource(mesh.get('filename', ''), urdf_path.parent, search, urdf_path.name))
        for mesh in _mesh_elements(root)
    ]
    return root, meshes


def resolved_urdf_text(urdf_path: str | Path, package_dirs: Iterable[str | Path] = ()) -> str:
    """The URDF's text with every mesh ``filename`` an absolute path (:func:`resolve_resource`).

    Raises:
        ConfigError: a mesh cannot be found.
    """
    root, meshes = _resolved(Path(urdf_path), package_dirs)
    for mesh, path in meshes:
        mesh.set('filename', str(path))
    return ET.tostring(root, encoding='unicode')


def loadable_urdf(urdf_path: str | Path, package_dirs: Iterable[str | Path] = ()) -> Path:
    """A URDF file with the same content whose meshes any loader finds (PyBullet takes a file):
    ``urdf_path`` itself when it names no mesh, else a copy with absolute mesh paths, kept in
    the temporary folder under a name of its content (written once, atomically).

    Raises:
        ConfigError: a mesh cannot be found.
    """
    urdf_path = Path(urdf_path)
    if not check_resources(urdf_path, package_dirs):
        return urdf_path
    text = resolved_urdf_text(urdf_path, package_dirs)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / 'wmm_control-urdf'
    folder.mkdir(exist_ok=True)
    out = folder / f'{urdf_path.stem}-{digest}.urdf'
    if not out.is_file():
        with tempfile.NamedTemporaryFile('w', dir=folder, suffix='.part', delete=False) as part:
            part.write(text)
        os.replace(part.name, out)
    return out


def load_geometry(model, urdf_path: str | Path, geometry_type, package_dirs: Iterable[str | Path] = ()):
    """pinocchio's geometry model (``pin.GeometryType.COLLISION`` or ``VISUAL``) of the URDF
    for ``model``, its meshes resolved here.

    Raises:
        ConfigError: a mesh cannot be found, or pinocchio cannot load the shapes.
    """
    import pinocchio as pin

    text = resolved_urdf_text(urdf_path, package_dirs)
    try:
        return pin.buildGeomFromUrdfString(model, text, geometry_type)
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f'pinocchio could not load the shapes of {urdf_path}: {exc}') from exc
