"""Parameter sweeps of the randomized runs: ``wmm_randomized --sweep NAME=V1,V2,...``.

A sweep names a parameter of the redundancy resolver, as ``--param`` does, and its values
(each read as YAML, as ``--param`` reads its value), each checked against the parameter's
range or choices (:data:`wmm_control.nodes.redundancy_resolver_params.PARAMS`, what the node
enforces). Several sweeps make a grid (every combination); every point of it runs the same
goals. :func:`plot_sweep` draws, per robot and method, the share of runs that converged and
their time to converge against the swept value.
"""

import itertools
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from wmm_control.errors import ConfigError, WmmError
from wmm_control.experiments.scenario import resolver_parameters
from wmm_control.nodes.redundancy_resolver_params import PARAMS
from wmm_control.resolvers import METHODS

__all__ = ['parse_sweeps', 'sweep_grid', 'check_point', 'point_label', 'plot_sweep']

#: The parameters a sweep may name: the methods' own (gains, thresholds, options), by name.
SWEEPABLE = {
    spec.name: spec
    for spec in PARAMS
    if any(spec.name in params.__dataclass_fields__ for _, params in METHODS.values())
}


def _value(name: str, text: str) -> Any:
    spec = SWEEPABLE[name]
    value = yaml.safe_load(text)
    if spec.choices is not None:
        if value not in spec.choices:
            raise WmmError(f'--sweep {name}: {text!r} is not one of {list(spec.choices)}')
    elif spec.lo is not None and spec.hi is not None:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise WmmError(f'--sweep {name}: expected a number within [{spec.lo:g}, {spec.hi:g}], got {text!r}')
        if not spec.lo <= value <= spec.hi:
            raise WmmError(f'--sweep {name}: {text} is outside its range [{spec.lo:g}, {spec.hi:g}]')
    return value


def parse_sweeps(texts: Iterable[str]) -> dict[str, list[Any]]:
    """The ``--sweep NAME=V1,V2,...`` arguments as ``{name: [values]}``, in their order.

    Raises:
        WmmError: a malformed argument, a name that is not a method parameter, a name given
            twice, or a value outside the parameter's range or choices (one line, naming it).
    """
    out: dict[str, list[Any]] = {}
    for text in texts:
        name, sep, values = text.partition('=')
        if not sep or not name or not values.strip(','):
            raise WmmError(f'--sweep: expected NAME=V1,V2,..., got {text!r}')
        if name not in SWEEPABLE:
            raise WmmError(f'--sweep: unknown parameter {name!r}; one of {", ".join(sorted(SWEEPABLE))}')
        if name in out:
            raise WmmError(f'--sweep: {name} given twice')
        out[name] = [_value(name, v) for v in values.split(',') if v.strip()]
    return out


def sweep_grid(sweeps: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """Every combination of the swept values, ``[{name: value}]`` (``[{}]`` without a sweep)."""
    return [dict(zip(sweeps, values)) for values in itertools.product(*sweeps.values())]


def check_point(method: str, run: Mapping[str, Any], point: Mapping[str, Any]) -> None:
    """Raise a one-line WmmError when ``method``'s parameters class refuses the run entry
    ``run`` with the point ``point`` of the grid (a value valid alone but not with the others,
    e.g. a collision influence below the safety distance)."""
    params = resolver_parameters({**run, **point})
    try:
        METHODS[method][1](**params)
    except (ConfigError, TypeError, ValueError) as exc:
        raise WmmError(f'--sweep {point_label(point)}: method {method}: {exc}') from None


def point_label(point: Mapping[str, Any]) -> str:
    """``name=value,...`` of a grid point ('' without a sweep)."""
    return ','.join(f'{k}={v}' for k, v in point.items())


def plot_sweep(summary: Sequence[Mapping[str, Any]], sweeps: Mapping[str, Sequence[Any]], path: str | Path) -> Path:
    """Plot, per robot and method, the converged share and the time to converge (median, with
    the largest as a bar) against the grid point, from the summary rows of ``--out`` (each with
    its ``sweep`` point); write it to ``path``.

    One swept parameter is the x axis; with several, the grid points are, labelled.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    points = sweep_grid(sweeps)
    single = len(sweeps) == 1
    x = [p[next(iter(sweeps))] for p in points] if single else list(range(len(points)))
    fig, (share, time) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True)
    series: dict[tuple[str, str], dict[int, Mapping[str, Any]]] = {}
    for row in summary:
        series.setdefault((row['robot'], row['method']), {})[points.index(dict(row['sweep']))] = row
    # the series side by side at each value, so that their bars do not hide each other
    step = 0.012 * ((max(x) - min(x)) or 1.0)
    for k, ((robot, method), rows) in enumerate(series.items()):
        at = sorted(rows)
        xs = [x[i] for i in at]
        share.plot(xs, [rows[i]['converged'] / rows[i]['runs'] for i in at], 'o-', label=f'{robot} {method}')
        timed = [i for i in at if rows[i]['median_time_s'] is not None]
        median = [rows[i]['median_time_s'] for i in timed]
        top = [rows[i]['max_time_s'] - rows[i]['median_time_s'] for i in timed]
        shifted = [x[i] + (k - (len(series) - 1) / 2) * step for i in timed]
        time.errorbar(shifted, median, yerr=[[0.0] * len(timed), top], fmt='o-', capsize=3)
    share.set_ylabel('converged share')
    share.set_ylim(-0.05, 1.05)
    share.legend(fontsize='small')
    time.set_ylabel('time to converge [s]\n(median, bar to the largest)')
    if single:
        time.set_xlabel(next(iter(sweeps)))
    else:
        time.set_xticks(x, [point_label(p).replace(',', '\n') for p in points], fontsize='small')
    for ax in (share, time):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
