//! Python bindings of refloc (`import refloc`): open a compiled map, localize
//! scans given as numpy arrays, compile a map. A thin layer: every number
//! comes from the `refloc` runtime or the `mapc` compiler unchanged. Units
//! are metres and radians, poses in the map frame (REP-103).

use std::path::PathBuf;

use numpy::{AllowTypeChange, PyArray1, PyArray2, PyArrayLike1, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyOSError, PyTypeError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    refloc,
    RefDbError,
    PyException,
    "A .refdb file that is not a valid database (the message says what and where)."
);
create_exception!(
    refloc,
    LocalizeError,
    PyException,
    "A scan that cannot be localized (bad geometry, too few points, no match)."
);
create_exception!(
    refloc,
    BuildError,
    PyException,
    "A map that cannot be compiled."
);

/// A compiled map (`.refdb`), memory-mapped and checked (structure and
/// checksums) when opened.
#[pyclass(frozen, module = "refloc")]
struct RefDb {
    db: refloc::RefDb<memmap2::Mmap>,
    path: PathBuf,
}

#[pymethods]
impl RefDb {
    /// Opens and checks the database at `path`.
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        py.detach(|| {
            let map = refloc::map_file(&path)
                .map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))?;
            let db = refloc::RefDb::new(map)
                .map_err(|e| RefDbError::new_err(format!("{}: {e}", path.display())))?;
            db.verify()
                .map_err(|e| RefDbError::new_err(format!("{}: {e}", path.display())))?;
            Ok(RefDb { db, path })
        })
    }

    /// Number of reference sites.
    #[getter]
    fn site_count(&self) -> usize {
        self.db.site_count()
    }

    /// Map-frame position (x, y in m) of reference site `i` (a free place
    /// on the map's Voronoi diagram).
    fn site_position(&self, i: usize) -> PyResult<(f32, f32)> {
        if i >= self.db.site_count() {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "site {i} of {}",
                self.db.site_count()
            )));
        }
        let p = self.db.site_xy(i);
        Ok((p[0], p[1]))
    }

    /// Bytes of scratch memory a scan of `beams` beams needs.
    fn scratch_size(&self, beams: usize) -> usize {
        refloc::scratch_size(self.db.params(), beams)
    }

    /// The acceptance threshold of the confidence stored in the database
    /// (None for a database built without a decision model).
    #[getter]
    fn accept_confidence(&self) -> Option<f32> {
        self.db.decision().map(|d| d.threshold)
    }

    /// Localizes one scan with no initial pose (see `Localizer.localize`);
    /// allocates the scratch memory for this call.
    #[pyo3(signature = (ranges, angle_min, angle_increment, range_min=0.0, range_max=30.0, region=None, heading=None))]
    #[allow(clippy::too_many_arguments)] // Python keyword arguments
    fn localize(
        slf: Bound<'_, Self>,
        ranges: PyArrayLike1<'_, f32, AllowTypeChange>,
        angle_min: f32,
        angle_increment: f32,
        range_min: f32,
        range_max: f32,
        region: Option<Region>,
        heading: Option<(f32, f32)>,
    ) -> PyResult<Localization> {
        let beams = ranges.len()?;
        // At least one beam of scratch: an empty scan is the runtime's error to report.
        let mut loc = Localizer::new(slf, beams.max(1))?;
        loc.localize(
            ranges,
            angle_min,
            angle_increment,
            range_min,
            range_max,
            region,
            heading,
        )
    }

    /// A virtual scan of the map (ranges in m, inf = no return) of a sensor
    /// at map-frame pose (x, y, theta) with `beams` beams evenly over
    /// `fov` rad centred ahead, as `mapc eval` simulates them: for trying
    /// the package without a robot. Returns (ranges, angle_min,
    /// angle_increment).
    #[pyo3(signature = (x, y, theta, beams=360, fov=std::f32::consts::TAU, range_max=30.0))]
    #[allow(clippy::too_many_arguments)] // Python keyword arguments
    fn simulate_scan<'py>(
        &self,
        py: Python<'py>,
        x: f32,
        y: f32,
        theta: f32,
        beams: usize,
        fov: f32,
        range_max: f32,
    ) -> PyResult<(Bound<'py, PyArray1<f32>>, f32, f32)> {
        let ok = (3..=1 << 16).contains(&beams)
            && fov > 0.0
            && fov <= std::f32::consts::TAU
            && range_max > 0.0
            && range_max.is_finite();
        if !ok {
            return Err(PyValueError::new_err(
                "beams must be 3..=65536, fov in (0, 2 pi] rad, range_max > 0 m",
            ));
        }
        let lidar = mapc::compiler::sim::Lidar::new(beams, fov, range_max);
        let ranges = mapc::compiler::sim::virtual_scan(
            &self.db.grid(),
            &self.db.frame(),
            &refloc::Pose2::new(x, y, theta),
            &lidar,
        );
        Ok((
            PyArray1::from_vec(py, ranges),
            lidar.angle_min,
            lidar.angle_increment,
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "RefDb('{}', sites={})",
            self.path.display(),
            self.db.site_count()
        )
    }
}

/// Localizes scans against one database, reusing its own scratch memory
/// (sized for scans of up to `max_beams` beams).
#[pyclass(module = "refloc")]
struct Localizer {
    db: Py<RefDb>,
    scratch: Vec<u8>,
}

#[pymethods]
impl Localizer {
    #[new]
    #[pyo3(signature = (db, max_beams=2048))]
    fn new(db: Bound<'_, RefDb>, max_beams: usize) -> PyResult<Self> {
        check_max_beams(max_beams)?;
        let size = refloc::scratch_size(db.get().db.params(), max_beams);
        Ok(Localizer {
            db: db.unbind(),
            scratch: vec![0u8; size],
        })
    }

    /// Localizes one scan: `ranges` (m; inf or nan for no return) of beams
    /// at `angle_min + k * angle_increment` (rad, sensor frame,
    /// counter-clockwise), as in `sensor_msgs/LaserScan`. A float32
    /// contiguous array is read in place; anything else is converted. The
    /// GIL is released while localizing.
    ///
    /// Priors: `region=(x, y, radius)` (m, map frame): the robot is within
    /// radius of (x, y); or `region=[(x1, y1), (x2, y2), ...]` (m, map
    /// frame; 3 to 32 vertices, a sequence of pairs or an N x 2 array): the
    /// robot is inside that polygon (its edges included; the last vertex
    /// joins the first); `heading=(theta, tolerance)` (rad, map frame): it
    /// faces theta +- tolerance. Sites (beyond 2 m outside the region) and
    /// poses outside them are not considered; without them nothing changes.
    #[pyo3(signature = (ranges, angle_min, angle_increment, range_min=0.0, range_max=30.0, region=None, heading=None))]
    #[allow(clippy::too_many_arguments)] // Python keyword arguments
    fn localize(
        &mut self,
        ranges: PyArrayLike1<'_, f32, AllowTypeChange>,
        angle_min: f32,
        angle_increment: f32,
        range_min: f32,
        range_max: f32,
        region: Option<Region>,
        heading: Option<(f32, f32)>,
    ) -> PyResult<Localization> {
        let prior = make_prior(region, heading)?;
        let py = ranges.py();
        let db = self.db.bind(py).get();
        let view = ranges.as_slice()?;
        let scratch = &mut self.scratch;
        py.detach(|| {
            let scan = range_scan(view, angle_min, angle_increment, range_min, range_max);
            refloc::localize_with_prior(&db.db, &scan, scratch, prior)
                .map(|l| Localization::of(&l))
                .map_err(|e| LocalizeError::new_err(e.to_string()))
        })
    }
}

/// Localizes scans against several databases (floors, buildings) and says
/// which map each scan is on, by the rule of `mapc localize A.refdb B.refdb
/// ... SCANS` (`refloc::select::which_map`): the accepted answer with the
/// highest confidence, the earlier map on a tie, if its probability among
/// the maps still reaches its map's threshold; or no map. Each database
/// has its own scratch memory, sized for scans of up to `max_beams` beams.
#[pyclass(module = "refloc")]
struct MapSet {
    dbs: Vec<Py<RefDb>>,
    scratch: Vec<Vec<u8>>,
}

#[pymethods]
impl MapSet {
    #[new]
    #[pyo3(signature = (dbs, max_beams=2048))]
    fn new(dbs: Vec<Bound<'_, RefDb>>, max_beams: usize) -> PyResult<Self> {
        if dbs.is_empty() {
            return Err(PyValueError::new_err("MapSet needs at least one RefDb"));
        }
        check_max_beams(max_beams)?;
        let scratch = dbs
            .iter()
            .map(|db| vec![0u8; refloc::scratch_size(db.get().db.params(), max_beams)])
            .collect();
        Ok(MapSet {
            dbs: dbs.into_iter().map(Bound::unbind).collect(),
            scratch,
        })
    }

    /// The databases, in the order given.
    #[getter]
    fn dbs(&self, py: Python<'_>) -> Vec<Py<RefDb>> {
        self.dbs.iter().map(|d| d.clone_ref(py)).collect()
    }

    /// Localizes one scan (the arguments of `Localizer.localize`, without
    /// priors) against every database, the GIL released, and says which
    /// map it is on.
    #[pyo3(signature = (ranges, angle_min, angle_increment, range_min=0.0, range_max=30.0))]
    fn localize(
        &mut self,
        ranges: PyArrayLike1<'_, f32, AllowTypeChange>,
        angle_min: f32,
        angle_increment: f32,
        range_min: f32,
        range_max: f32,
    ) -> PyResult<WhichMap> {
        let py = ranges.py();
        let view = ranges.as_slice()?;
        let dbs: Vec<&refloc::RefDb<memmap2::Mmap>> =
            self.dbs.iter().map(|d| &d.get().db).collect();
        let scratch = &mut self.scratch;
        let answers: Vec<Result<Localization, String>> = py.detach(|| {
            let scan = range_scan(view, angle_min, angle_increment, range_min, range_max);
            dbs.iter()
                .zip(scratch.iter_mut())
                .map(|(db, s)| {
                    refloc::localize(db, &scan, s)
                        .map(|l| Localization::of(&l))
                        .map_err(|e| e.to_string())
                })
                .collect()
        });
        let map_index = refloc::select::which_map(answers.iter().zip(dbs.iter()).map(|(a, db)| {
            let threshold = db.decision().unwrap_or(refloc::Decision::DEFAULT).threshold;
            a.as_ref().map_or((false, 0.0, threshold), |l| {
                (l.accepted, l.confidence, threshold)
            })
        }));
        let mut maps = Vec::with_capacity(answers.len());
        let mut reasons = Vec::with_capacity(answers.len());
        for a in answers {
            match a {
                Ok(l) => {
                    maps.push(Some(Py::new(py, l)?));
                    reasons.push(None);
                }
                Err(e) => {
                    maps.push(None);
                    reasons.push(Some(e));
                }
            }
        }
        Ok(WhichMap {
            map_index,
            maps,
            reasons,
        })
    }
}

/// Which map a scan is on (`MapSet.localize`), with its answer on each.
#[pyclass(frozen, module = "refloc")]
struct WhichMap {
    map_index: Option<usize>,
    maps: Vec<Option<Py<Localization>>>,
    reasons: Vec<Option<String>>,
}

#[pymethods]
impl WhichMap {
    /// Index of the map the scan is on (in the order given), or None when
    /// no map accepts it.
    #[getter]
    fn map_index(&self) -> Option<usize> {
        self.map_index
    }

    /// Some map accepts the scan (`map_index` is not None).
    #[getter]
    fn accepted(&self) -> bool {
        self.map_index.is_some()
    }

    /// The answer on the map the scan is on, or None.
    #[getter]
    fn localization(&self, py: Python<'_>) -> Option<Py<Localization>> {
        self.map_index
            .and_then(|i| self.maps[i].as_ref().map(|l| l.clone_ref(py)))
    }

    /// The answer on each map, in order; None where the scan could not be
    /// localized (`reasons` says why).
    #[getter]
    fn maps(&self, py: Python<'_>) -> Vec<Option<Py<Localization>>> {
        self.maps
            .iter()
            .map(|m| m.as_ref().map(|l| l.clone_ref(py)))
            .collect()
    }

    /// Why the scan could not be localized on each map (the runtime's
    /// message), None where it was.
    #[getter]
    fn reasons(&self) -> Vec<Option<String>> {
        self.reasons.clone()
    }

    fn __repr__(&self) -> String {
        match self
            .map_index
            .and_then(|i| self.maps[i].as_ref().map(|l| (i, l.get())))
        {
            Some((i, l)) => format!(
                "WhichMap(map_index={i}, x={:.3}, y={:.3}, theta={:.4}, confidence={:.4})",
                l.x, l.y, l.theta, l.confidence
            ),
            None => "WhichMap(map_index=None)".to_string(),
        }
    }
}

/// Which of the databases `dbs` the scan is on (see `MapSet`); allocates
/// the scratch memory for this call.
#[pyfunction]
#[pyo3(signature = (dbs, ranges, angle_min, angle_increment, range_min=0.0, range_max=30.0))]
fn localize_maps(
    dbs: Vec<Bound<'_, RefDb>>,
    ranges: PyArrayLike1<'_, f32, AllowTypeChange>,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
) -> PyResult<WhichMap> {
    let beams = ranges.len()?;
    MapSet::new(dbs, beams.max(1))?.localize(
        ranges,
        angle_min,
        angle_increment,
        range_min,
        range_max,
    )
}

/// `max_beams` of a `Localizer` or `MapSet`: 1..=65536.
fn check_max_beams(max_beams: usize) -> PyResult<()> {
    if max_beams == 0 || max_beams > 1 << 16 {
        return Err(PyValueError::new_err(format!(
            "max_beams must be 1..=65536, got {max_beams}"
        )));
    }
    Ok(())
}

/// The runtime's scan of `ranges` with the `sensor_msgs/LaserScan` fields.
fn range_scan(
    ranges: &[f32],
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
) -> refloc::Scan<'_> {
    refloc::Scan::Ranges(refloc::RangeScan {
        angle_min,
        angle_increment,
        range_min,
        range_max,
        ranges,
    })
}

/// `region=`: a circle `(x, y, radius)` or a polygon, a sequence of at
/// least 3 `(x, y)` vertices (m, map frame).
#[derive(Debug)]
enum Region {
    Circle(f32, f32, f32),
    Polygon(Vec<[f32; 2]>),
}

impl<'py> FromPyObject<'_, 'py> for Region {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, 'py, PyAny>) -> PyResult<Self> {
        if let Ok((x, y, r)) = obj.extract::<(f32, f32, f32)>() {
            return Ok(Region::Circle(x, y, r));
        }
        if let Ok(v) = obj.extract::<Vec<[f32; 2]>>() {
            return Ok(Region::Polygon(v));
        }
        Err(PyTypeError::new_err(
            "region is (x, y, radius) or a sequence of at least 3 (x, y) vertices (m, map frame)",
        ))
    }
}

/// The runtime's prior of `region=` (a circle or a polygon) and
/// `heading=(theta, tolerance)` (see `Localizer.localize`), checked.
fn make_prior(
    region: Option<Region>,
    heading: Option<(f32, f32)>,
) -> PyResult<Option<refloc::Prior>> {
    let mut prior = match &region {
        None => None,
        Some(Region::Circle(x, y, r)) => Some(refloc::Prior::circle(*x, *y, *r)),
        Some(Region::Polygon(v)) => Some(
            refloc::Prior::polygon(v).map_err(|e| PyValueError::new_err(format!("region: {e}")))?,
        ),
    };
    if let Some((theta, tol)) = heading {
        prior = Some(
            prior
                .unwrap_or(refloc::Prior::NONE)
                .with_heading(theta, tol),
        );
    }
    match prior {
        Some(p) if !p.is_valid() => Err(PyValueError::new_err(format!(
            "region needs finite x, y and radius > 0 m, heading a finite theta and tolerance >= 0 rad; got region={region:?}, heading={heading:?}"
        ))),
        p => Ok(p),
    }
}

/// One distinct pose hypothesis.
#[pyclass(frozen, get_all, module = "refloc")]
#[derive(Clone)]
struct Hypothesis {
    /// Robot x in the map frame (m).
    x: f32,
    /// Robot y in the map frame (m).
    y: f32,
    /// Robot heading in the map frame (rad).
    theta: f32,
    /// Probability (0-1) that this pose is right.
    confidence: f32,
}

#[pymethods]
impl Hypothesis {
    fn __repr__(&self) -> String {
        format!(
            "Hypothesis(x={:.3}, y={:.3}, theta={:.4}, confidence={:.4})",
            self.x, self.y, self.theta, self.confidence
        )
    }
}

/// The answer for one scan, as the runtime reports it.
#[pyclass(frozen, get_all, module = "refloc")]
struct Localization {
    /// Robot x in the map frame (m).
    x: f32,
    /// Robot y in the map frame (m).
    y: f32,
    /// Robot heading in the map frame (rad).
    theta: f32,
    /// The pose is accepted (confidence at least the database's threshold).
    accepted: bool,
    /// Probability (0-1) that the pose is right.
    confidence: f32,
    /// Another distinct pose explains the scan nearly as well.
    ambiguous: bool,
    /// Distinct hypotheses: this pose first, then the alternatives by
    /// probability, highest first.
    hypotheses: Vec<Hypothesis>,
    /// The reference site the pose came through.
    site: u32,
    /// Its coarse rank (0 = best).
    coarse_rank: u32,
    /// Vicinity score M and its threshold.
    vicinity: f32,
    vicinity_threshold: f32,
    /// Evidence (M less the short-beam penalty).
    evidence: f32,
    /// Input beams with a return.
    valid_points: u32,
    /// Heading change (rad) over the scanner's sweep the pose was fitted
    /// with (a scan taken while turning); 0 for a rigid fit.
    skew: f32,
    /// Candidates examined.
    candidates: usize,
    cov: Option<[f32; 9]>,
}

impl Localization {
    fn of(l: &refloc::Localization<'_>) -> Localization {
        Localization {
            x: l.pose.x,
            y: l.pose.y,
            theta: l.pose.theta,
            accepted: l.accepted,
            confidence: l.confidence,
            ambiguous: l.ambiguous,
            hypotheses: l
                .hypotheses()
                .iter()
                .map(|h| Hypothesis {
                    x: h.pose.x,
                    y: h.pose.y,
                    theta: h.pose.theta,
                    confidence: h.confidence,
                })
                .collect(),
            site: l.site,
            coarse_rank: l.coarse_rank,
            vicinity: l.vicinity,
            vicinity_threshold: l.vicinity_threshold,
            evidence: l.evidence,
            valid_points: l.valid_points,
            skew: l.skew,
            candidates: l.candidates.len(),
            cov: l.covariance,
        }
    }
}

#[pymethods]
impl Localization {
    /// (x, y, theta) of the robot in the map frame (m, m, rad).
    #[getter]
    fn pose(&self) -> (f32, f32, f32) {
        (self.x, self.y, self.theta)
    }

    /// 3x3 covariance of (x, y, theta) (m^2, m rad, rad^2), or None when
    /// the fit could not give one.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f32>>>> {
        match self.cov {
            Some(c) => Ok(Some(PyArray1::from_slice(py, &c).reshape([3, 3])?)),
            None => Ok(None),
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Localization(x={:.3}, y={:.3}, theta={:.4}, accepted={}, confidence={:.4})",
            self.x,
            self.y,
            self.theta,
            if self.accepted { "True" } else { "False" },
            self.confidence
        )
    }
}

/// Compiles the ROS map (`map_yaml`: map_server YAML with its PGM/PNG) into
/// a `.refdb` at `out_path` with `mapc build`'s defaults except the options
/// given; returns the number of reference sites. The GIL is released while
/// compiling (which uses every core).
#[pyfunction]
#[pyo3(signature = (map_yaml, out_path, beams=362, range_max=30.0, seed=1, accept_confidence=0.8))]
fn build(
    py: Python<'_>,
    map_yaml: PathBuf,
    out_path: PathBuf,
    beams: u32,
    range_max: f32,
    seed: u64,
    accept_confidence: f32,
) -> PyResult<usize> {
    py.detach(|| {
        let cfg = mapc::compiler::pipeline::BuildConfig {
            beams,
            range_max,
            seed,
            accept_confidence,
            ..Default::default()
        };
        cfg.params()
            .map_err(|e| BuildError::new_err(e.to_string()))?;
        mapc::compiler::writer::check_output_path(&out_path, &[&map_yaml])
            .map_err(|e| PyOSError::new_err(format!("{}: {e}", out_path.display())))?;
        let src = mapc::compiler::mapfile::load_yaml(&map_yaml)
            .map_err(|e| BuildError::new_err(format!("{}: {e}", map_yaml.display())))?;
        // The image the YAML names is an input too.
        mapc::compiler::writer::check_output_path(&out_path, &src.input_files())
            .map_err(|e| PyOSError::new_err(format!("{}: {e}", out_path.display())))?;
        let built = mapc::compiler::pipeline::build(&src, &cfg)
            .map_err(|e| BuildError::new_err(format!("{}: {e}", map_yaml.display())))?;
        let secs: Vec<_> = built
            .sections
            .iter()
            .map(|(k, b)| (*k, b.as_slice()))
            .collect();
        mapc::compiler::writer::write_refdb(&out_path, &secs)
            .map_err(|e| PyOSError::new_err(format!("{}: {e}", out_path.display())))?;
        Ok(built.sites.len())
    })
}

/// refloc: where am I on this map, from one laser scan, with no initial pose.
#[pymodule(name = "refloc")]
fn refloc_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RefDb>()?;
    m.add_class::<Localizer>()?;
    m.add_class::<Localization>()?;
    m.add_class::<Hypothesis>()?;
    m.add_class::<MapSet>()?;
    m.add_class::<WhichMap>()?;
    m.add_function(wrap_pyfunction!(build, m)?)?;
    m.add_function(wrap_pyfunction!(localize_maps, m)?)?;
    let py = m.py();
    m.add("RefDbError", py.get_type::<RefDbError>())?;
    m.add("LocalizeError", py.get_type::<LocalizeError>())?;
    m.add("BuildError", py.get_type::<BuildError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
