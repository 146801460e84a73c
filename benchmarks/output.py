"""What ``softshadow bench`` shows: a progress line on stderr while it runs, tables when it is done."""

from __future__ import annotations

import sys

__all__ = ["StepProgress", "format_tables"]


class StepProgress:
    """A tqdm status bar on stderr: the bench's current step and the time since it started. Notes
    that matter afterwards (a peer skipped, say) are also printed as lines of their own."""

    def __init__(self):
        from tqdm import tqdm
        self._bar = tqdm(total=None, unit="step", file=sys.stderr, dynamic_ncols=True,
                         bar_format="{desc} [{elapsed}]", disable=None)

    def __call__(self, message: str) -> None:
        if message.startswith(("skipped", "warning")):
            self._bar.write(message, file=sys.stderr)
        self._bar.set_description_str(message)
        self._bar.update(1)

    def close(self) -> None:
        self._bar.close()


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)) and len(value) <= 4 and all(isinstance(v, (int, float)) for v in value):
        return "x".join(_cell(v) for v in value)
    return str(value)


def _flat(row: dict) -> dict:
    """A row's scalar cells; nested dicts of scalars become "key.sub" cells."""
    out = {}
    for key, value in row.items():
        if isinstance(value, dict):
            out.update({f"{key}.{k}": v for k, v in value.items() if not isinstance(v, (dict, list))})
        elif not isinstance(value, list) or len(value) <= 4:
            out[key] = value
    return out


def _table(title: str, rows: list[dict]) -> str:
    rows = [_flat(r) for r in rows]
    columns = list(dict.fromkeys(k for r in rows for k in r))
    cells = [[_cell(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    line = "  ".join(c.ljust(w) for c, w in zip(columns, widths))
    body = ["  ".join(v.rjust(w) for v, w in zip(row, widths)) for row in cells]
    return "\n".join([title, line, "  ".join("-" * w for w in widths), *body])


def _tables(prefix: str, value, out: list[str]) -> None:
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        out.append(_table(prefix, value))
    elif isinstance(value, dict):
        scalars = {k: v for k, v in value.items() if not isinstance(v, (dict, list))}
        nested = {k: v for k, v in value.items() if isinstance(v, (dict, list))}
        if scalars and prefix and any(isinstance(v, float) for v in scalars.values()):
            out.append(_table(prefix, [scalars]))
        for key, sub in nested.items():
            _tables(f"{prefix}.{key}" if prefix else key, sub, out)


def format_tables(result: dict) -> str:
    """The bench's result (its JSON document) as plain-text tables, one per list of cases, headed by
    where it sits in the JSON; the environment in one line at the top."""
    env = result.get("environment", {})
    head = ", ".join(f"{k} {env[k]}" for k in ("machine", "cpu_count", "load_average", "finished_utc")
                     if k in env)
    out: list[str] = [f"environment: {head}"] if head else []
    _tables("", {k: v for k, v in result.items() if k != "environment"}, out)
    return "\n\n".join(out)
