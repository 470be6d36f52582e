"""Units of the quantities a file declares and of the quantities derived from them, as UDUNITS strings.

A problem or scenario file may say in which units its numbers are (``units: {length: km, time: h}``);
the defaults are metre and second, and ``"1"`` declares a dimensionless (scaled) axis. Every variable
written to a netCDF file gets its ``units`` attribute from :meth:`UnitSystem.of`, which composes the
declared units into one UDUNITS-2 product (``UnitSystem(length="km", time="h").of(length=1, time=-2)``
is ``"km h-2"``), so any CF tool can convert the values (tests parse every unit written with UDUNITS-2,
through ``cf_units``).

Length and time units are chosen from a list (editors complete them from the JSON Schema and a typo
gets "expected one of …"); free physical units (a field's ``°C``, a state's ``mg L-1``) are checked for
UDUNITS syntax only, since no units database is needed at run time.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import AfterValidator

__all__ = ["LengthUnit", "TimeUnit", "PhysicalUnit", "UnitSystem", "DIMENSIONLESS"]

#: the UDUNITS string of a dimensionless quantity
DIMENSIONLESS = "1"

#: length units a file may declare (UDUNITS symbols); "1" for a dimensionless (scaled) length
LengthUnit = Literal["m", "km", "cm", "mm", "um", "nmi", "mi", "ft", "yd", "1"]
#: time units a file may declare (UDUNITS symbols); "1" for a dimensionless (scaled) time
TimeUnit = Literal["s", "ms", "min", "h", "d", "1"]

_SYNTAX = re.compile(r"^[A-Za-z0-9_°µ%()/.^* +-]+$")


def _udunits_syntax(value: str) -> str:
    text = value.strip()
    depth = 0
    for char in text:
        depth += {"(": 1, ")": -1}.get(char, 0)
        if depth < 0:
            break
    if not text or not _SYNTAX.match(text) or depth != 0 or text[0] in "/.^*":
        raise ValueError(
            f"expected a UDUNITS unit string such as 'm', 'degC', 'mg L-1' or '1' (dimensionless), got {value!r}"
        )
    return text


#: a free physical unit (UDUNITS syntax), e.g. the unit of a field or of the process state
PhysicalUnit = Annotated[str, AfterValidator(_udunits_syntax)]


def _group(symbol: str) -> str:
    """A unit usable as a factor of a product: compound units are parenthesised."""
    return f"({symbol})" if any(c in symbol for c in " /.*^()") else symbol


@dataclass(frozen=True)
class UnitSystem:
    """The declared units of a file: ``length``, ``time`` and any named ``others`` (``field``, ``state``, …).

    Parameters
    ----------
    length, time : str
        UDUNITS strings (default metre and second; ``"1"`` for a dimensionless axis).
    others : dict
        Further base quantities by name, e.g. ``{"field": "degC", "state": "1", "cost": "1"}``.
    """

    length: str = "m"
    time: str = "s"
    others: dict[str, str] = field(default_factory=dict)

    def base(self, name: str) -> str:
        """The unit of base quantity ``name`` (``"length"``, ``"time"`` or a key of ``others``)."""
        if name == "length":
            return self.length
        if name == "time":
            return self.time
        return self.others.get(name, DIMENSIONLESS)

    def of(self, **powers: int) -> str:
        """The UDUNITS product of base units raised to ``powers``; ``"1"`` when nothing dimensional is left.

        ``of(length=1, time=-1)`` is a velocity (``"m s-1"``), ``of()`` a pure number. Identical base units
        are merged (``of(cost=1, state=-2)`` with both ``"1"`` is ``"1"``).
        """
        exponents: dict[str, int] = {}
        for name, power in powers.items():
            symbol = self.base(name)
            if symbol != DIMENSIONLESS and power:
                exponents[symbol] = exponents.get(symbol, 0) + power
        terms = []
        for symbol, power in exponents.items():
            if power == 0:
                continue
            factor = _group(symbol)
            exponent = "" if power == 1 else (f"^{power}" if factor.endswith(")") else str(power))
            terms.append(factor + exponent)
        return " ".join(terms) or DIMENSIONLESS

    def label(self, **powers: int) -> str:
        """The unit for an axis label: ``"m s-1"``, or ``"dimensionless"`` instead of ``"1"``."""
        text = self.of(**powers)
        return "dimensionless" if text == DIMENSIONLESS else text
