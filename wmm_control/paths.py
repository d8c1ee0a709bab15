"""Locate the package's data files (robot descriptions and parameter files).

An installed package (``colcon build``, ``pip install``) keeps them under
``<prefix>/share/wmm_control``; a source checkout keeps them next to the code.
The installed share directory wins when it exists.
"""

import os
import sys
from pathlib import Path
from typing import Any

import yaml

from wmm_control.errors import ConfigError

PACKAGE = 'wmm_control'
_SOURCE_ROOT = Path(__file__).resolve().parent.parent

__all__ = ['share_dir', 'config_path', 'robot_names', 'parse_yaml', 'load_defaults']


def _candidates():
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            yield Path(prefix) / 'share' / PACKAGE
    yield Path(sys.prefix) / 'share' / PACKAGE
    # colcon install layout: <prefix>/lib/pythonX.Y/site-packages/wmm_control
    yield _SOURCE_ROOT.parent.parent.parent / 'share' / PACKAGE


def share_dir() -> Path:
    """Return the directory that holds ``config/`` for this package.

    The source tree is used when it has a ``config`` folder (a checkout or an
    editable install); otherwise the first installed share directory found.
    """
    if (_SOURCE_ROOT / 'config').is_dir():
        return _SOURCE_ROOT
    for cand in _candidates():
        if (cand / 'config').is_dir():
            return cand
    return _SOURCE_ROOT


def config_path(*parts: str) -> Path:
    """Path of a file under ``config/``, e.g. ``config_path('robots', 'steerable.yaml')``."""
    return share_dir().joinpath('config', *parts)


def robot_names() -> list[str]:
    """The robots shipped in ``config/robots`` (YAML stems), sorted."""
    return sorted(p.stem for p in config_path('robots').glob('*.yaml'))


def parse_yaml(text: str) -> Any:
    """The document of the YAML ``text``, as ``yaml.safe_load`` reads it; with libyaml's parser
    where PyYAML was built with it (the same documents, about ten times faster: every node reads
    its robot and parameter files as it starts).

    Raises:
        yaml.YAMLError: ``text`` is not YAML.
    """
    return yaml.load(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))


def load_defaults(yaml_name: str, node_name: str) -> dict:
    """``ros__parameters`` of ``node_name`` (or ``/**``) from ``config/<yaml_name>``: a node's
    parameter defaults, which the direct engine takes too."""
    path = config_path(yaml_name)
    try:
        doc = parse_yaml(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f'cannot read parameter defaults {path}: {exc}') from exc
    for key in (node_name, '/' + node_name, '/**'):
        section = doc.get(key)
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            return section['ros__parameters']
    raise ConfigError(f'{path}: no "{node_name}: ros__parameters:" section')
