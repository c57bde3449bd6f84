# Hand-written stub of the native module (python/src/lib.rs). The typed API is kodama_dag.api;
# these are the plain values it is built from.
from typing import Any, Callable

__version__: str

class UserError(Exception):
    """What the CLI reports with exit code 2: a graph, parameter or input file that is not what
    was expected. The message names the file, the place and what was expected."""

class EngineError(Exception):
    """What the CLI reports with exit code 1: the cache or the output folder failed."""

def run(
    graph: str,
    sets: list[str],
    cache: str,
    out: str | None,
    targets: list[str],
    jobs: int | None,
    data: str | None,
    allow_outside: bool,
    tile_m: float | None,
    halo_m: float | None,
    quiet: bool,
    progress: Callable[[str], object] | None = None,
) -> tuple[str, dict[str, Any]]: ...
def explain(
    graph: str,
    sets: list[str],
    cache: str,
    targets: list[str],
    data: str | None,
    allow_outside: bool,
) -> str: ...
def kinds() -> list[dict[str, Any]]: ...
def artifact(cache: str, digest: str) -> dict[str, Any]: ...
def cli(argv: list[str]) -> int: ...
def sweep(
    file: str,
    sets: list[str],
    cache: str,
    out: str | None,
    jobs: int | None,
    data: str | None,
    allow_outside: bool,
    quiet: bool,
    progress: Callable[[str], object] | None = None,
) -> dict[str, Any]: ...
def trace(
    scene: str | tuple[str, str],
    links: Any,
    freq_hz: float,
    physics: dict[str, Any],
) -> dict[str, Any]: ...
def radio_map_at(
    scene: str | tuple[str, str],
    tx: tuple[float, float, float],
    freq_hz: float,
    cell_m: float,
    height_m: float,
    physics: dict[str, Any],
) -> dict[str, Any]: ...
def export(
    cache: str,
    digest: str,
    site: tuple[str, tuple[float, float], float],
    dest: str,
    overwrite: bool,
    band: tuple[str | None, str | None] = (None, None),
) -> list[str]: ...
def lon_lat(
    crs: str, origin: tuple[float, float], xs: list[float], ys: list[float]
) -> tuple[Any, Any]: ...
def foliage_lengths(plys: list[str], points: Any, counts: list[int]) -> Any: ...
def foliage_loss_db(
    lengths: list[float],
    freq_hz: float,
    db_per_m: float | None = None,
    max_db: float | str | None = None,
) -> Any: ...
