"""refloc: where am I on this map, from one laser scan, with no initial pose.

Units are metres and radians; poses are in the map frame (REP-103).
"""
from os import PathLike
from typing import Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class RefDbError(Exception):
    """A .refdb file that is not a valid database (the message says what and where)."""

class LocalizeError(Exception):
    """A scan that cannot be localized (bad geometry, too few points, no match)."""

class BuildError(Exception):
    """A map that cannot be compiled."""

_Ranges = Union[npt.NDArray[np.float32], npt.NDArray[np.float64], Sequence[float]]
# A prior region (m, map frame): a circle (x, y, radius), or a polygon of 3 to
# 32 (x, y) vertices.
_Region = Union[Tuple[float, float, float], Sequence[Tuple[float, float]],
                Sequence[Sequence[float]], npt.NDArray[np.floating]]

class Hypothesis:
    """One distinct pose hypothesis."""
    x: float
    y: float
    theta: float
    confidence: float

class Localization:
    """The answer for one scan, as the runtime reports it."""
    x: float
    y: float
    theta: float
    accepted: bool
    confidence: float
    ambiguous: bool
    hypotheses: list[Hypothesis]
    site: int
    coarse_rank: int
    vicinity: float
    vicinity_threshold: float
    evidence: float
    valid_points: int
    #: Heading change (rad) over the scanner's sweep the pose was fitted
    #: with (a scan taken while turning); 0.0 for a rigid fit.
    skew: float
    candidates: int
    @property
    def pose(self) -> Tuple[float, float, float]:
        """(x, y, theta) of the robot in the map frame (m, m, rad)."""
    @property
    def covariance(self) -> Optional[npt.NDArray[np.float32]]:
        """3x3 covariance of (x, y, theta) (m^2, m rad, rad^2), or None."""

class RefDb:
    """A compiled map (.refdb), memory-mapped and checked when opened."""
    def __init__(self, path: Union[str, PathLike[str]]) -> None: ...
    @property
    def site_count(self) -> int: ...
    @property
    def accept_confidence(self) -> Optional[float]:
        """The confidence threshold stored in the database (None: built without one)."""
    def site_position(self, i: int) -> Tuple[float, float]:
        """Map-frame (x, y) of reference site i (a free place)."""
    def scratch_size(self, beams: int) -> int:
        """Bytes of scratch memory a scan of `beams` beams needs."""
    def localize(self, ranges: _Ranges, angle_min: float, angle_increment: float,
                 range_min: float = 0.0, range_max: float = 30.0,
                 region: Optional[_Region] = None,
                 heading: Optional[Tuple[float, float]] = None) -> Localization:
        """Localizes one scan (see Localizer.localize); allocates its scratch per call."""
    def simulate_scan(self, x: float, y: float, theta: float, beams: int = 360,
                      fov: float = 6.283185307179586, range_max: float = 30.0
                      ) -> Tuple[npt.NDArray[np.float32], float, float]:
        """A virtual scan of the map at a map-frame pose: (ranges, angle_min, angle_increment)."""

class Localizer:
    """Localizes scans against one database, reusing its own scratch memory."""
    def __init__(self, db: RefDb, max_beams: int = 2048) -> None: ...
    def localize(self, ranges: _Ranges, angle_min: float, angle_increment: float,
                 range_min: float = 0.0, range_max: float = 30.0,
                 region: Optional[_Region] = None,
                 heading: Optional[Tuple[float, float]] = None) -> Localization:
        """Localizes one scan: ranges (m; inf or nan for no return) of beams at
        angle_min + k * angle_increment (rad, sensor frame, counter-clockwise),
        as in sensor_msgs/LaserScan. A contiguous float32 array is read in place;
        anything else is converted. The GIL is released while localizing.
        Priors: region=(x, y, radius) (m, map frame), a circle, or
        region=[(x1, y1), (x2, y2), ...] (m, map frame; 3 to 32 vertices, a
        sequence of pairs or an N x 2 array), a polygon (edges included, the
        last vertex joins the first), and heading=(theta, tolerance) (rad,
        map frame); sites and poses outside them are not considered. Raises LocalizeError when the scan cannot be localized,
        ValueError for a prior that makes no sense."""

class WhichMap:
    """Which map a scan is on (MapSet.localize), with its answer on each."""
    @property
    def map_index(self) -> Optional[int]:
        """Index of the map the scan is on (in the order given), or None when no map accepts it."""
    @property
    def accepted(self) -> bool:
        """Some map accepts the scan (map_index is not None)."""
    @property
    def localization(self) -> Optional[Localization]:
        """The answer on the map the scan is on, or None."""
    @property
    def maps(self) -> list[Optional[Localization]]:
        """The answer on each map, in order; None where the scan could not be localized."""
    @property
    def reasons(self) -> list[Optional[str]]:
        """Why the scan could not be localized on each map (the runtime's message), None where it was."""

class MapSet:
    """Localizes scans against several databases (floors, buildings) and says
    which map each scan is on, by the rule of `mapc localize A.refdb B.refdb
    ... SCANS`: the accepted answer with the highest confidence (the earlier
    map on a tie) if it stays likely with the other maps' answers weighed
    against it (its probability among the maps reaches its map's threshold),
    or no map. Each database has its own scratch memory."""
    def __init__(self, dbs: Sequence[RefDb], max_beams: int = 2048) -> None: ...
    @property
    def dbs(self) -> list[RefDb]: ...
    def localize(self, ranges: _Ranges, angle_min: float, angle_increment: float,
                 range_min: float = 0.0, range_max: float = 30.0) -> WhichMap:
        """Localizes one scan (as Localizer.localize, without priors) against
        every database, the GIL released, and says which map it is on. A scan
        that cannot be localized on a map is no answer there, not an error."""

def localize_maps(dbs: Sequence[RefDb], ranges: _Ranges, angle_min: float,
                  angle_increment: float, range_min: float = 0.0,
                  range_max: float = 30.0) -> WhichMap:
    """Which of the databases the scan is on (see MapSet); allocates the scratch per call."""

def build(map_yaml: Union[str, PathLike[str]], out_path: Union[str, PathLike[str]],
          beams: int = 362, range_max: float = 30.0, seed: int = 1,
          accept_confidence: float = 0.8) -> int:
    """Compiles a ROS map_server map (YAML + PGM/PNG) into a .refdb with
    `mapc build`'s defaults except the options given; returns the site count.
    The GIL is released while compiling."""
