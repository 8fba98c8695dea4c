"""Argument types the tools share: a clear argparse error for a value out of range."""

import argparse
import math


def positive(kind):
    """An argparse type: a positive ``kind`` (int or float), finite."""

    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not (v > 0 and math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{text} must be positive")
        return v

    return parse


def below_one(text):
    """An argparse type: a number in [0, 1) (an opening angle)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"{text} must be in [0, 1)")
    return v
