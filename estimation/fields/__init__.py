"""Scalar fields z(r, t) with exact derivatives: analytic library, advection–diffusion, gridded data."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "Field": "mobisense.estimation.fields.base",
        "FIELDS": "mobisense.estimation.fields.base",
        "register_field": "mobisense.estimation.fields.base",
        "make_field": "mobisense.estimation.fields.base",
        "level_curve_frame": "mobisense.estimation.fields.base",
        "QuadraticField": "mobisense.estimation.fields.library",
        "TwoChargesField": "mobisense.estimation.fields.library",
        "OceanTemperatureField": "mobisense.estimation.fields.library",
        "FieldSpec": "mobisense.estimation.fields.library",
        "AdvectionDiffusionField": "mobisense.estimation.fields.advection_diffusion",
        "GriddedField": "mobisense.estimation.fields.gridded",
    },
)
