"""Numbers and text of the HTML pages (the review board's report.html, :mod:`hazard.outputs.review`;
the risk section, :mod:`hazard.outputs.risk_page`; map.html, :mod:`hazard.outputs.map_page`): report.json's
values with their units, and the jinja2 environment of the bundled templates. Below the
pages (imports none of them)."""

from __future__ import annotations

import math

__all__ = ["report_number", "plain_number", "fmt_number", "fmt_distance", "fmt_percent_change", "fmt_vector", "optics_text",
           "template_environment"]

_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def report_number(x):
    """A report.json number as a float: the strings ``"inf"``, ``"-inf"`` and ``"nan"``
    (JSON has no infinity) included; None, text and anything else stay as they are."""
    if isinstance(x, str) and x in ("inf", "-inf", "nan"):
        return float(x)
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return float(x)
    return x


def plain_number(v: float, sig: int) -> str:
    """``v`` with ``sig`` significant figures: fixed notation from 1e-3 to 1e7 (digits in
    groups of three from 10 000 on), else a power of ten (``3.1×10⁻⁸``)."""
    if v == 0:
        return "0"
    mag = math.floor(math.log10(abs(v)))
    if -3 <= mag < 7:
        text = f"{v:.{max(sig - 1 - mag, 0)}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        if abs(v) >= 1e4:
            head, _, tail = text.partition(".")
            sign, digits = ("-", head[1:]) if head.startswith("-") else ("", head)
            groups = [digits[max(i - 3, 0):i] for i in range(len(digits), 0, -3)][::-1]
            text = sign + "\u202f".join(groups) + ("." + tail if tail else "")
        return text
    mant, _, exp = f"{v:.{sig - 1}e}".partition("e")
    mant = mant.rstrip("0").rstrip(".") if "." in mant else mant
    return f"{mant}\u00d710{str(int(exp)).translate(_SUPERSCRIPT)}"


def fmt_number(x, unit: str = "", *, sig: int = 4, inf: str = "infinite", none: str = "none") -> str:
    """One value of report.json as text, with its unit.

    Parameters
    ----------
    x : float, int, str or None
        The value; ``"inf"``/``"-inf"``/``"nan"`` are report.json's non-finite numbers.
    unit : str
        Unit appended after a no-break space (``"m"``, ``"W/m²"``); none for ratios.
    sig : int
        Significant figures (4: the precision of ``hazard run``'s text).
    inf : str
        Text of +infinity (``"unbounded"`` for distances).
    none : str
        Text of a missing value (JSON null).

    Returns
    -------
    str
    """
    v = report_number(x)
    if v is None:
        return none
    if isinstance(v, bool):
        return "yes" if v else "no"
    if not isinstance(v, float):
        return str(v)
    if math.isnan(v):
        return "undefined (NaN)"
    if math.isinf(v):
        return inf if v > 0 else f"-{inf}"
    text = plain_number(v, sig)
    return f"{text}\u00a0{unit}" if unit else text


def fmt_distance(x, *, none: str = "none") -> str:
    """A distance [m] (a NOHD, a range) as text; infinity is ``"unbounded"``."""
    return fmt_number(x, "m", inf="unbounded", none=none)


def fmt_percent_change(before, after) -> str:
    """``after`` against ``before`` as a signed percentage (``"+14.0 %"``), or ``""``."""
    b, a = report_number(before), report_number(after)
    if not (isinstance(a, float) and isinstance(b, float)) or not (math.isfinite(a) and math.isfinite(b)) or b == 0:
        return ""
    return f"{100.0 * (a - b) / b:+.1f}\u00a0%"


def fmt_vector(v, unit: str = "", *, sig: int = 6) -> str:
    """A list of numbers as ``[a, b, c] unit``; anything else as :func:`fmt_number`."""
    if not isinstance(v, (list, tuple)):
        return fmt_number(v, unit, sig=sig, none="not given")
    text = "[" + ", ".join(fmt_vector(x, sig=sig) for x in v) + "]"
    return f"{text}\u00a0{unit}" if unit else text


def optics_text(a: dict) -> str:
    """An optical aid as ``7×50`` (magnification × objective diameter [mm])."""
    d = report_number(a.get("objective_diameter_m"))
    return f"{fmt_number(a.get('magnification'))}\u00d7{fmt_number(1e3 * d) if isinstance(d, float) else '?'}"


def template_environment():
    """The jinja2 environment of the bundled templates (hazard/templates: autoescape,
    undefined names an error)."""
    import jinja2

    return jinja2.Environment(loader=jinja2.PackageLoader("hazard", "templates"), autoescape=True,
                              undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
