"""Measured data for the discrepancy workflow: per-condition errors of real subjects (format eyehil.measured/1).

A small JSON file; angles in degrees.

    {
      "format": "eyehil.measured/1",
      "experiment": "guestrin2006",              # or "blignaut2014": the simulated experiment to compare with
      "source": "Guestrin & Eizenman 2006 ...",  # free text
      "unit": "deg",
      "subjects": ["S1", "S2", "S3", "S4"],      # optional: per-subject lists below are in this order
      "conditions": {
        "H1": [0.258, 0.430, 0.435, 0.412],      # one value per subject, or
        "C5": {"mean": 1.37, "sd": 0.41, "n": 26} # a summary ("sd" may be omitted or null)
      }
    }

Condition names are those the experiment computes (`eyehil.analysis.discrepancy.metrics`): for guestrin2006
"H1", "H2", "head:<head position name>", "bias_x:H1|H2", "bias_y:H1|H2"; for blignaut2014 the
best-function errors "C5" ... "C135" and "M<k>:<configuration>" (model k). With "subjects", lists are
paired: a condition that has a reference (H2 and head:* refer to H1) is compared as the within-subject
difference from its reference. Without "subjects", lists are independent samples.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "eyehil.measured/1"


@dataclass(frozen=True, eq=False)
class MeasuredCondition:
    """One condition: per-subject `values` (n,), or only a summary (`mean`, `sd` or None, `n`)."""

    values: np.ndarray | None = None
    mean: float = float("nan")
    sd: float | None = None
    n: int = 0

    @classmethod
    def of(cls, spec: Any) -> MeasuredCondition:
        """From a JSON value: a list of numbers or {"mean", "sd", "n"}."""
        if isinstance(spec, dict):
            if "mean" not in spec or "n" not in spec:
                raise ValueError("a summary condition needs 'mean' and 'n'")
            sd = spec.get("sd")
            return cls(None, float(spec["mean"]), None if sd is None else float(sd), int(spec["n"]))
        values = np.asarray(spec, dtype=float).ravel()
        if values.size < 2 or not np.all(np.isfinite(values)):
            raise ValueError("per-subject values must be at least 2 finite numbers")
        return cls(values, float(values.mean()), float(values.std(ddof=1)), int(values.size))

    def to_json(self) -> Any:
        if self.values is not None:
            return [round(float(v), 6) for v in self.values]
        return {"mean": self.mean, "sd": self.sd, "n": self.n}


@dataclass(frozen=True, eq=False)
class Measured:
    """Per-condition measured errors of one experiment (module docstring)."""

    experiment: str
    conditions: dict[str, MeasuredCondition]
    subjects: tuple[str, ...] | None = None
    source: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def paired(self) -> bool:
        return self.subjects is not None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"format": FORMAT, "experiment": self.experiment, "source": self.source,
                               "unit": "deg"}
        if self.subjects is not None:
            out["subjects"] = list(self.subjects)
        out["conditions"] = {k: c.to_json() for k, c in self.conditions.items()}
        return {**out, **self.extra}

    @classmethod
    def from_dict(cls, data: dict[str, Any], origin: str = "measured data") -> Measured:
        if not isinstance(data, dict):
            raise ValueError(f"{origin}: not a JSON object with 'experiment' and 'conditions'")
        try:
            if data.get("format", FORMAT) != FORMAT:
                raise ValueError(f"format {data.get('format')!r} is not {FORMAT}")
            if data.get("unit", "deg") != "deg":
                raise ValueError("unit must be 'deg'")
            missing = [k for k in ("experiment", "conditions") if k not in data]
            if missing:
                raise ValueError(f"missing field(s) {', '.join(map(repr, missing))}")
            conditions = {}
            for k, v in dict(data["conditions"]).items():
                try:
                    conditions[str(k)] = MeasuredCondition.of(v)
                except (TypeError, ValueError) as exc:
                    raise ValueError(f"condition {k!r}: {exc}") from None
            subjects = tuple(str(s) for s in data["subjects"]) if data.get("subjects") else None
            known = {"format", "experiment", "source", "unit", "subjects", "conditions"}
            measured = cls(str(data["experiment"]), conditions, subjects, str(data.get("source", "")),
                           {k: v for k, v in data.items() if k not in known})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{origin}: {exc}") from None
        measured.check()
        return measured

    def check(self) -> None:
        """ValueError if there are no conditions or per-subject lists disagree with `subjects`."""
        if not self.conditions:
            raise ValueError("measured data: no conditions")
        for name, c in self.conditions.items():
            if self.subjects is not None and c.values is not None and c.values.size != len(self.subjects):
                raise ValueError(f"measured data: condition {name!r} has {c.values.size} values for "
                                 f"{len(self.subjects)} subjects")

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n", encoding="utf-8")
        return path


def load(path: str | Path) -> Measured:
    """A measured-data file (format above)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"measured data file {path} does not exist")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON: {exc}") from None
    return Measured.from_dict(data, str(path))


def guestrin2006_real() -> Measured:
    """The 4 subjects of Guestrin & Eizenman 2006: H1 and H2 per subject (deg, atan(mm / 650 mm))."""
    from eyehil.analysis.study.published import guestrin_real_deg, published

    real = guestrin_real_deg()
    return Measured("guestrin2006", {k: MeasuredCondition.of(v) for k, v in real.items()},
                    tuple(f"S{i + 1}" for i in range(len(real["H1"]))), published()["guestrin2006_real"]["source"])


def blignaut2014_real() -> Measured:
    """Blignaut 2014: the real best-function mean error per configuration (26 participants, no SD)."""
    from eyehil.analysis.study.published import blignaut_real, published

    real = blignaut_real()
    conditions = {c: MeasuredCondition(None, float(m), None, int(real["participants"]))
                  for c, m in real["best_error"].items()}
    return Measured("blignaut2014", conditions, None, published()["blignaut2014_real"]["source"])


BUILTIN = {"guestrin2006": guestrin2006_real, "blignaut2014": blignaut2014_real}
