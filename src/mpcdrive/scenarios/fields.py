"""The value types of scenario files: strict, finite numbers with their ranges and units, and the
strict base of every section (unknown keys are rejected, sections are frozen)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)]
#: a coordinate [m]; beyond a thousand kilometres float64 loses the millimetres
Coord = Annotated[float, Field(strict=True, ge=-1e6, le=1e6, allow_inf_nan=False)]
#: a vehicle dimension [m]
Length = Annotated[float, Field(strict=True, gt=0, le=100, allow_inf_nan=False)]
#: a speed [m/s] (360 km/h at most)
Speed = Annotated[float, Field(strict=True, ge=-100, le=100, allow_inf_nan=False)]
Int = Annotated[int, Field(strict=True)]
Point = tuple[Coord, Coord]


class Strict(BaseModel):
    """A scenario section: unknown keys rejected, frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)
