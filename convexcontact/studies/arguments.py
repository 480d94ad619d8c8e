"""Arguments of ``convexcontact demo``, ``bench`` and ``study …``, checked before any work.

Numbers are checked where argparse reads them (a ``type=``: argparse's message names the option,
``argument --nx: expected an integer ≥ 2, e.g. 16; got '0'``); sizes are estimated and refused,
naming the option, when the machine's memory or an hour would not hold the run.
"""

from __future__ import annotations

import argparse
import contextlib
import math

from ..drivers.estimates import LONG_RUN, duration
from ..scene.description import SceneError


def integer(minimum: int, example: int):
    """An argparse type: an integer of at least ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer ≥ {minimum}, e.g. {example}; got {text!r}")
        return value

    return parse


def number(example: str, positive: bool = True):
    """An argparse type: a finite number, and above zero if ``positive``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or (positive and value <= 0):
            wanted = "a positive finite number" if positive else "a finite number"
            raise argparse.ArgumentTypeError(f"expected {wanted}, e.g. {example}; got {text!r}")
        return value

    return parse


@contextlib.contextmanager
def named(option: str):
    """Turn a SceneError of a size check (:func:`~convexcontact.scene.meshing.check_size`,
    :func:`~convexcontact.scene.meshing.check_memory`) into a ValueError naming the command-line ``option``."""
    try:
        yield
    except SceneError as error:
        raise ValueError(f"{option}: {str(error).removeprefix(error.field + ': ')}") from None


SECONDS_PER_DOF = 5e-5
"""Seconds of one contact solve per free DOF, a low estimate: measured 5.7·10⁻⁵ (Signorini, the Hertz punch,
4·10⁴ DOFs) to 2.5·10⁻⁴ (Tresca, the sliding block, 10⁴ DOFs) on the shared 2-vCPU machines. It refuses runs of
hours; it does not predict run times."""

def check_duration(option: str, count: float, each: float, what: str, fix: str) -> None:
    """Refuse, naming ``option``, ``count`` runs (``what``) of about ``each`` seconds when they exceed
    :data:`~convexcontact.drivers.estimates.LONG_RUN`."""
    if count * each > LONG_RUN:
        raise ValueError(f"{option}: {count:.3g} {what} of about {each:.2g} s each would take about "
                         f"{duration(count * each)}, beyond the {LONG_RUN / 3600:g} h a run may take here; {fix} "
                         f"(about {LONG_RUN / each:.3g} of them fit)")
