"""Command-line options with units: ``hazard nohd --power "2 kW"`` as in scene files.

An option whose name ends in a unit (``--power-w``, ``--divergence-rad``) keeps taking a
bare number in that unit and also takes a quantity string (``--power-w "2 kW"``); its
alias without the suffix (``--power``) takes a quantity string only, as the scene files'
unsuffixed keys do (``--power 20``: W or kW?). The strings are parsed by
:mod:`scenes.quantities` (pint): a unit of the wrong dimension, an unknown unit or a bare
number on the alias is a usage error (exit 2, one line naming the option and the value).
"""

from __future__ import annotations

import argparse

__all__ = ["QuantityOption", "add_quantity_option", "parse_option"]


def parse_option(text: str, unit: str, option: str, *, bare_ok: bool, suffixed: str = "the option that names the unit") -> float:
    """The value of ``option`` [``unit``] from its command-line text.

    Parameters
    ----------
    text : str
        The text after the option: a number (only when ``bare_ok``) or a quantity string.
    unit : str
        The option's unit, pint text (``"W"``, ``"rad"``, ``"W/m^2"``).
    option : str
        The option as typed (``--power``), named in errors.
    bare_ok : bool
        Whether a bare number is read in ``unit`` (the suffixed option) or refused.
    suffixed : str
        The option that takes bare numbers, named when one is refused.

    Returns
    -------
    float
        The value in ``unit``.

    Raises
    ------
    scenes.quantities.QuantityError
        An unknown unit, a unit of another dimension, or a bare number where not allowed.
    """
    try:
        number = float(text)
    except ValueError:
        from scenes.quantities import convert_value  # only for a quantity: a bare number loads neither pydantic nor pint

        return convert_value(text, unit, option, bare_ok=bare_ok)
    if not bare_ok:
        from scenes.quantities import QuantityError

        raise QuantityError(f"{option} = {text!r}: a bare number without its unit is ambiguous here; write it with a unit "
                            f"('{text} {unit}' if {unit} is meant) or use {suffixed} (in {unit})")
    return number


class QuantityOption(argparse.Action):
    """An argparse action storing a float in ``unit``: see :func:`parse_option`. Option
    strings ending in ``suffix`` take bare numbers; the others quantity strings only."""

    def __init__(self, option_strings, dest, unit=None, suffix=None, **kwargs):
        super().__init__(option_strings, dest, **kwargs)
        self.unit, self.suffix = unit, suffix

    def __call__(self, parser, namespace, values, option_string=None):
        try:
            value = parse_option(values, self.unit, option_string, bare_ok=option_string.endswith(self.suffix),
                                 suffixed=self.option_strings[0])
        except ValueError as exc:  # scenes.quantities.QuantityError
            raise argparse.ArgumentError(self, str(exc)) from None
        setattr(namespace, self.dest, value)


def add_quantity_option(parser, flag: str, unit: str, help: str, **kwargs):
    """``parser.add_argument(flag, alias, ...)`` for a suffixed flag (``--power-w``) in
    ``unit``, with the alias without the suffix (``--power``) taking quantity strings.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
        Where the option is added.
    flag : str
        The option with its unit suffix (``--power-w``, ``--mpe-w-m2``, ``--attenuation-per-m``).
    unit : str
        The unit of the stored value, pint text (``"W"``, ``"W/m^2"``, ``"1/m"``).
    help : str
        The option's help; the accepted forms are appended.
    **kwargs
        Passed to ``add_argument`` (``required``, ``default``).

    Returns
    -------
    argparse.Action
        The added option.
    """
    parts = flag[2:].split("-")
    for n in (3, 2, 1):  # the longest unit suffix: w-m2, per-m, km, ...
        tail = "-".join(parts[-n:])
        if len(parts) > n and tail.replace("-", "_") in _SUFFIXES:
            stem, suffix = "-".join(parts[:-n]), "-" + tail
            break
    else:
        raise ValueError(f"{flag}: no unit suffix")
    return parser.add_argument(flag, f"--{stem}", action=QuantityOption, unit=unit, suffix=suffix, metavar="Q",
                               help=f"{help}; a number in {unit} or a quantity ('{_EXAMPLES[unit]}'); --{stem} takes a quantity only",
                               **kwargs)


_SUFFIXES = ("w_m2", "per_m", "nm", "km", "m", "s", "w", "rad", "deg", "hz")
_EXAMPLES = {"W": "2 kW", "W/m^2": "5 mW/cm^2", "nm": "1.064 um", "s": "250 ms", "rad": "0.5 mrad", "deg": "5 deg", "m": "7 mm",
             "km": "23 km", "1/m": "0.2 1/km", "Hz": "10 kHz"}
