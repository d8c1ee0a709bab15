"""colcon builds an installable ament_python package whose executables start.

This is the layout ``ros2 run wmm_control <exe>`` relies on: the ament index marker,
``share/wmm_control/package.xml``, the config files, and one executable per console
script under ``lib/wmm_control/``.
"""

import configparser
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
COLCON = Path(sys.executable).with_name('colcon')


def console_scripts(prefix):
    """Executable names the installed package declares (its entry_points.txt)."""
    parser = configparser.ConfigParser()
    parser.read(next(prefix.glob('lib/python3*/site-packages/wmm_control*.egg-info/entry_points.txt')))
    return sorted(parser['console_scripts'])


@pytest.fixture(scope='module')
def install_tree(tmp_path_factory):
    if not COLCON.exists():
        pytest.fail(f'colcon not found next to {sys.executable}: run the README set-up')
    work = tmp_path_factory.mktemp('colcon')
    result = subprocess.run(
        [str(COLCON), '--log-base', str(work / 'log'), 'build', '--base-paths', str(REPO),
         '--build-base', str(work / 'build'), '--install-base', str(work / 'install')],
        cwd=work, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    return work / 'install' / 'wmm_control'


def installed_env(prefix):
    env = dict(os.environ)
    site = next(prefix.glob('lib/python3*/site-packages'))
    env['PYTHONPATH'] = os.pathsep.join([str(site), env.get('PYTHONPATH', '')])
    env['AMENT_PREFIX_PATH'] = str(prefix)
    return env


def test_install_tree_has_the_ament_layout(install_tree):
    share = install_tree / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'wmm_control').is_file()
    assert (share / 'wmm_control' / 'package.xml').read_text() == (REPO / 'package.xml').read_text()
    for src in (REPO / 'config').rglob('*'):
        if src.is_file():
            assert (share / 'wmm_control' / src.relative_to(REPO)).is_file(), src


def test_every_console_script_is_installed_under_lib_and_starts(install_tree):
    names = console_scripts(install_tree)
    assert 'wmm_model' in names
    env = installed_env(install_tree)
    for name in names:
        exe = install_tree / 'lib' / 'wmm_control' / name
        assert exe.is_file() and os.access(exe, os.X_OK), exe
        if name == 'wmm_model':
            out = subprocess.run([str(exe), '--robot', 'B'], env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stderr
            # The installed copy reads its robot files from the installed share directory.
            assert f'urdf: {install_tree / "share" / "wmm_control" / "config" / "robots" / "mecanum.urdf"}' \
                in out.stdout
            continue
        # A node: it must come up and keep running until interrupted, then exit cleanly.
        proc = subprocess.Popen([str(exe)], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            time.sleep(4.0)
            assert proc.poll() is None, f'{name} exited early:\n{proc.stdout.read()}'
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 0, f'{name} exit code {proc.returncode}:\n{proc.stdout.read()}'


def test_wmm_model_reports_a_clear_error_for_an_unknown_robot(install_tree):
    exe = install_tree / 'lib' / 'wmm_control' / 'wmm_model'
    out = subprocess.run([str(exe), '--robot', 'C'], env=installed_env(install_tree),
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "unknown robot 'C'" in out.stderr
