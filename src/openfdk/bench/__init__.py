"""Benchmarks behind ``openfdk bench``.

Each benchmark module exposes ``run(quick: bool) -> list[dict]`` returning records
``{"name": str, "value": float, "unit": str}`` (medians over repeats). Modules are
listed in :data:`BENCHMARK_MODULES` and imported lazily so that one broken benchmark
does not hide the others.
"""

BENCHMARK_MODULES = [
    "openfdk.bench.kinematics",
    "openfdk.bench.arm5",
    "openfdk.bench.recruitment",
    "openfdk.bench.inverse_dynamics",
    "openfdk.bench.contact",
    "openfdk.bench.fdk",
    "openfdk.bench.mandible",
    "openfdk.bench.knee",
    "openfdk.bench.tka_knee_gait",
    "openfdk.bench.full_body",
    "openfdk.bench.full_body_id",
    "openfdk.bench.full_body_muscles",
    "openfdk.bench.force_plates",
    "openfdk.bench.study",
    "openfdk.bench.fuzz",
    "openfdk.bench.memory",
]
