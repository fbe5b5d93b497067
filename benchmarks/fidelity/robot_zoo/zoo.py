"""The robot zoo's table (``robots.toml``): each robot's model file, found inside the installed PyPI package that
ships it (``importlib.metadata``, no path of this machine), its gains file and provenance."""

from __future__ import annotations

import importlib.metadata
import tomllib
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
TABLE = HERE / "robots.toml"


@dataclass(frozen=True)
class ZooRobot:
    """One ``robots.toml`` table."""

    name: str
    """The table's name: the robot's output folder and summary key."""
    package: str
    """The PyPI distribution that ships the model."""
    file: str
    """The model's path inside the package's share folder (``cmeel.prefix/share/<package>/...``)."""
    gains: Path
    """The wresdyn gains config (absolute)."""
    dof: int
    """Actuated joints the model has."""
    source: str
    """Where the model comes from."""
    licence: str
    """The model's own licence."""

    @property
    def path(self) -> Path:
        """The model file as installed (raises ``FileNotFoundError`` naming the package when it is not)."""
        return package_file(self.package, self.file)

    @property
    def version(self) -> str:
        """The installed package's version."""
        return importlib.metadata.version(self.package)


def package_file(package: str, file: str) -> Path:
    """The installed file of ``package`` whose recorded path ends with ``file`` (the package's RECORD lists it)."""
    try:
        dist = importlib.metadata.distribution(package)
    except importlib.metadata.PackageNotFoundError:
        raise FileNotFoundError(f"{package} is not installed (pip install {package})") from None
    suffix = "/" + file.strip("/")
    hits = [f for f in dist.files or () if ("/" + str(f)).endswith(suffix)]
    if len(hits) != 1:
        raise FileNotFoundError(f"{package} {dist.version}: {len(hits)} installed files end with {file}")
    return Path(dist.locate_file(hits[0])).resolve()


def load_zoo(table: Path = TABLE) -> dict[str, ZooRobot]:
    """Every robot of ``table``, in its order."""
    raw = tomllib.loads(table.read_text())
    return {name: ZooRobot(name, t["package"], t["file"], (table.parent / t["gains"]).resolve(), int(t["dof"]),
                           t["source"], t["licence"]) for name, t in raw.items()}
