//! Candidate selection and acceptance: which coarse candidates the fine
//! stage examines (the early stop and its confirmation), which examined
//! candidate is the answer, whether another one makes it ambiguous, and
//! whether it is accepted.
//!
//! Everything here works on [`Candidate`] records alone (no database, no
//! scan), so each rule can be tested on constructed cases.

use crate::confidence::{self, Decision};
use crate::localize::{Candidate, Hypothesis};
use crate::params::{Params, Selection};
use crate::verify;
use crate::Pose2;

/// After the early stop's condition holds at a candidate of coarse score
/// gamma, the candidates still to come with a score of at least
/// `gamma - EARLY_CONFIRM_GAMMA` are examined too (ranked by gamma, they are
/// the next ones), except those whose site lies within
/// [`CONFIRM_SKIP_RADIUS`] of the best pose so far. Measured on a symmetric
/// map (tb3-world, 200 static 360-degree poses): the twin site ranks within
/// 0.02 of the one that stopped the search; without the confirmation 15.5%
/// of the poses were accepted at the twin, with it none (docs/ssm.md,
/// "Early stop and its confirmation").
pub const EARLY_CONFIRM_GAMMA: f32 = 0.05;

/// Confirmation after the early stop skips candidate sites closer than this
/// (m) to the best pose so far: their match would find the same pose, and
/// the ambiguity test looks for poses over [`DISTINCT_DISTANCE`] away.
pub const CONFIRM_SKIP_RADIUS: f32 = 2.0;

/// Most candidates the confirmation after the early stop examines.
pub const CONFIRM_MAX: usize = 6;

/// Two poses are distinct alternatives when their positions differ by more
/// than this (m) ...
pub const DISTINCT_DISTANCE: f32 = 1.0;

/// ... or their headings by more than this (rad, 20 degrees). Both are the
/// scale of a different place or a turned match, well beyond the localizer's
/// error on a right match (millimetres, tenths of a degree: docs/results.md).
pub const DISTINCT_HEADING: f32 = 20.0 * core::f32::consts::PI / 180.0;

/// The early stop's confident match: at most one beam in this many is
/// short (blocked by something unmapped in front).
pub const EARLY_SHORT_SHARE: u32 = 5;

/// The early stop on real scans: once the best answer so far has a
/// confidence ([`Decision::probability`], capped by [`capped_confidence`] as
/// the answer's is) of at least this, the search confirms it (as after a
/// confident match) and stops. Real scans of a map made by another run
/// rarely explain 90% of their beams (`early_accept`), so without it every
/// query examined all N_C candidates. Chosen on the real Intel and ACES
/// logs (`mapc localize` candidate lists replayed under candidate stop
/// rules, docs/performance.md "Stopping on confidence"): with the
/// four-feature model, 0.99 kept the accepted and false-accepted answers
/// of both logs those of the full search, and 0.98 and 0.95 added 0.1 to
/// 0.9 points of false accepts. With the spread feature the model is
/// better calibrated (docs/confidence.md) and right answers reach 0.99
/// later; at 0.98 the decisions on the three shared logs are those at
/// 0.99 (Intel: two more right answers) with 13-30% less median time.
pub const EARLY_CONFIDENCE: f32 = 0.98;

/// The confidence stop ([`EARLY_CONFIDENCE`]) waits for at least this many
/// coarse candidates (examined or not): support, one of the confidence's
/// features, counts the candidates that found the same pose, and needs a
/// few to mean anything. 4 to 12 gave the same decisions in the replay; 6,
/// the middle, was taken first. Since the sixteenth session 4, the low
/// end: every decision on the three real logs, the independent simulator's
/// 40 sets and `mapc eval`'s sets measured is the same as with 6, and the
/// median real query takes 3-10% fewer instructions (docs/performance.md,
/// "The low end of two waits").
pub const EARLY_CONFIDENCE_MIN: usize = 4;

/// The settled-answer stop: once the best answer so far has been the best
/// over the last [`SETTLED_CANDIDATES`] examined candidates and has a
/// confidence of at least this, the search confirms it (as after a
/// confident match) and stops. Many right answers of real scans never reach
/// [`EARLY_CONFIDENCE`] (on ACES two thirds), so every candidate was
/// examined for them; a right pose found early is rarely displaced by a
/// late candidate. Chosen on the real Intel and ACES logs by replaying
/// full-search candidate lists (docs/performance.md, "Stopping on a settled
/// answer"): 0.9 after 20 kept their false accepts, looser settings (0.8,
/// or 12 candidates) added some; CSAIL, held out, checked it.
pub const SETTLED_CONFIDENCE: f32 = 0.9;

/// How many examined candidates after the best one make an answer settled
/// ([`SETTLED_CONFIDENCE`]).
pub const SETTLED_CANDIDATES: usize = 20;

/// The firm-answer stop, beside the settled one: an answer with a
/// confidence of at least this that has stayed the best over
/// [`FIRM_CANDIDATES`] examined candidates is confirmed and the search
/// stops. On ACES the settled stop still examined a median of 28
/// candidates. Chosen on the real Intel and ACES logs by replaying
/// full-search candidate lists (`scripts/replay-stops.py`,
/// docs/performance.md "A firm answer stops sooner"): 0.95 after 8, 10 or
/// 12 gave ACES's decisions of the settled stop alone but one, with a
/// median of 20-23 candidates instead of 28, and on Intel two to four
/// decisions changed (one to three more false accepts of 910, a
/// tenth of a point each); 10, the middle, was taken first. CSAIL, held
/// out: no decision changed. Since the sixteenth session 8, with
/// [`EARLY_CONFIDENCE_MIN`] (the same decisions on every set measured;
/// docs/performance.md, "The low end of two waits"). A single rule whose
/// wait shrinks as the confidence grows (20 candidates at 0.9 down to none
/// at 0.98) examined fewer but added half a point of false accepts on ACES.
pub const FIRM_CONFIDENCE: f32 = 0.95;

/// How many examined candidates after the best one make an answer firm
/// ([`FIRM_CONFIDENCE`]).
pub const FIRM_CANDIDATES: usize = 8;

/// True when the poses of `a` and `b` are distinct alternatives (see
/// [`DISTINCT_DISTANCE`], [`DISTINCT_HEADING`]).
pub fn distinct(a: &Candidate, b: &Candidate) -> bool {
    let (dx, dy) = (a.x - b.x, a.y - b.y);
    dx * dx + dy * dy > DISTINCT_DISTANCE * DISTINCT_DISTANCE
        || libm::fabsf(crate::wrap_angle(a.theta - b.theta)) > DISTINCT_HEADING
}

/// Where a pose found after the search ([`crate::Localizer::corridor_pass`])
/// goes among the candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Placement {
    /// A candidate at the same place ([`distinct`]) explains the scan at
    /// least as well, or the pose would join places the candidates keep
    /// apart: it adds nothing.
    Known,
    /// No candidate is at its place: a new hypothesis.
    New,
    /// A better fit of this candidate's place, whose pose it replaces.
    Refits(usize),
}

/// Where `pose` (a candidate record with its pose and evidence) goes among
/// `cands`: [`Placement::New`] when no candidate with a pose is at its
/// place; [`Placement::Refits`] the one with the most evidence there (the
/// earlier on a tie) when `pose` has more evidence than every candidate
/// there and every other candidate is as distinct from `pose` as from it
/// (a refit neither merges a rival into the answer nor lends support);
/// else [`Placement::Known`].
pub fn placement(cands: &[Candidate], pose: &Candidate) -> Placement {
    let mut there: Option<usize> = None;
    for (j, o) in cands.iter().enumerate() {
        if o.has_pose == 0 || distinct(o, pose) {
            continue;
        }
        if o.evidence >= pose.evidence {
            return Placement::Known;
        }
        if there.is_none_or(|t| o.evidence > cands[t].evidence) {
            there = Some(j);
        }
    }
    let Some(j) = there else {
        return Placement::New;
    };
    let old = &cands[j];
    let same = cands
        .iter()
        .enumerate()
        .all(|(k, o)| k == j || o.has_pose == 0 || distinct(o, old) == distinct(o, pose));
    if same {
        Placement::Refits(j)
    } else {
        Placement::Known
    }
}

/// True when candidate `a` (with a pose) is a better answer than `b`: a
/// pose that passes the free-space check beats one that fails it; then the
/// larger matching score E ([`Selection::MatchScore`]) or evidence
/// ([`Selection::Vicinity`]) wins, the earlier candidate on a tie.
pub fn better(a: &Candidate, b: &Candidate, selection: Selection) -> bool {
    if a.free_space_ok != b.free_space_ok {
        return a.free_space_ok != 0;
    }
    match selection {
        Selection::MatchScore => a.match_score > b.match_score,
        Selection::Vicinity => a.evidence > b.evidence,
    }
}

/// `M / (`[`verify::HIT_SCORE`]` (N_P - short))` of a candidate: how well the beams that
/// are not blocked by something unmapped fit the map (0 when all are).
pub fn explained_ratio(c: &Candidate) -> f32 {
    verify::ratio(c.vicinity, c.pairs.saturating_sub(c.short_beams))
}

/// True when `c` passes the acceptance threshold and the free-space check.
pub fn passes(c: &Candidate) -> bool {
    c.has_pose != 0 && c.free_space_ok != 0 && c.evidence > c.vicinity_threshold
}

/// Fills `out` with the distinct hypotheses among `cands`, best first:
/// candidate `best` (the answer), then repeatedly the best candidate with a
/// pose (by [`better`]) that is distinct from every one chosen, each with
/// its probability under `decision`. Returns how many (0 when `best` has no
/// pose). The alternatives after the answer are then ordered by their
/// probability, highest first (ties keep the [`better`] order), so a reader
/// of the list sees the likeliest alternative second. The probabilities are
/// each a hypothesis's own; they need not sum to 1 (several may all be
/// unlikely).
pub fn hypotheses(
    cands: &[Candidate],
    best: usize,
    selection: Selection,
    decision: &Decision,
    out: &mut [Hypothesis],
) -> usize {
    let mut n = 0;
    let mut next = cands.get(best).filter(|c| c.has_pose != 0).map(|_| best);
    while let (Some(i), true) = (next, n < out.len()) {
        let c = &cands[i];
        out[n] = Hypothesis {
            pose: Pose2::new(c.x, c.y, c.theta),
            confidence: decision.probability(&confidence::features(cands, c)),
            candidate: i as u32,
        };
        n += 1;
        next = None;
        for (k, o) in cands.iter().enumerate() {
            let new = o.has_pose != 0
                && out[..n].iter().all(|h| {
                    cands
                        .get(h.candidate as usize)
                        .is_some_and(|t| distinct(o, t))
                });
            if new && next.is_none_or(|p| better(o, &cands[p], selection)) {
                next = Some(k);
            }
        }
    }
    // Stable insertion sort of the alternatives (at most a handful).
    for i in 2..n {
        let mut j = i;
        while j > 1 && out[j].confidence > out[j - 1].confidence {
            out.swap(j, j - 1);
            j -= 1;
        }
    }
    n
}

/// What to do with the next coarse candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Next {
    /// Run the fine stage on it.
    Examine,
    /// Skip it (its site is near the best pose: it would find that pose
    /// again); it stays in the list without a pose.
    Skip,
    /// Stop: it and the candidates after it are not examined.
    Stop,
}

/// The fine stage's search over the ranked candidates: the best answer so
/// far and the early stop's state.
///
/// Early stop ([`Selection::Vicinity`], `early_accept` > 0): after a
/// confident match (the beams not blocked by something unmapped fit the map
/// at least `early_accept` well, at most one in [`EARLY_SHORT_SHARE`] is
/// blocked, and the pose passes), or after `early_min` candidates with a
/// passing best, the search examines the candidates the coarse stage rates
/// within [`EARLY_CONFIRM_GAMMA`] of the one that stopped it (a twin place
/// ranks there, and the ambiguity test sees only what was examined), at
/// most [`CONFIRM_MAX`] of them, skipping those near the best pose. With a
/// confidence model ([`Search::with_decision`]) the best answer reaching
/// [`EARLY_CONFIDENCE`] after [`EARLY_CONFIDENCE_MIN`] candidates, or
/// [`SETTLED_CONFIDENCE`] after staying the best over
/// [`SETTLED_CANDIDATES`] more (or [`FIRM_CONFIDENCE`] over
/// [`FIRM_CANDIDATES`] more), starts the same confirmation. With a model,
/// a confirmation that ends on an answer the model would reject (a twin
/// found, or a match that explains the beams yet is not convincing) does
/// not end the search: it goes on down the list, where a later stop may
/// fire. On maps of many places alike (a warehouse's rack aisles) the
/// right place is often ranked below a look-alike that explains 90% of the
/// beams (docs/performance.md, "A rejected stop searches on").
#[derive(Clone, Copy, Debug)]
pub struct Search {
    selection: Selection,
    early_accept: f32,
    early_min: usize,
    ambiguity_ratio: f32,
    decision: Option<Decision>,
    best: Option<usize>,
    /// Set by the early stop: the coarse score below which the search ends.
    floor: Option<f32>,
    confirmed: usize,
}

impl Search {
    /// A search with the database's selection and early-stop settings.
    pub fn new(params: &Params) -> Search {
        Search {
            selection: params.select.selection,
            early_accept: params.select.early_accept,
            early_min: params.select.early_min as usize,
            ambiguity_ratio: params.select.ambiguity_ratio,
            decision: None,
            best: None,
            floor: None,
            confirmed: 0,
        }
    }

    /// The same search that also stops on the confidence of its best answer
    /// under `decision` ([`EARLY_CONFIDENCE`]); the localizer passes the
    /// database's model (or [`Decision::DEFAULT`]).
    pub fn with_decision(self, decision: Decision) -> Search {
        Search {
            decision: Some(decision),
            ..self
        }
    }

    /// The same search with no early stop of any kind: every candidate is
    /// examined (as with `early_accept` 0).
    pub fn exhaustive(self) -> Search {
        Search {
            early_accept: 0.0,
            early_min: 0,
            ..self
        }
    }

    /// The confidence (0..=1) of candidate `b` as the answer among `cands`
    /// under the search's model: its probability, capped when another
    /// distinct pose makes it ambiguous. 0 without a model.
    pub fn confidence(&self, cands: &[Candidate], b: usize) -> f32 {
        match (self.decision, cands.get(b)) {
            (Some(d), Some(c)) if c.has_pose != 0 => capped_confidence(
                d.probability(&confidence::features(cands, c)),
                ambiguous(cands, c, self.ambiguity_ratio),
            ),
            _ => 0.0,
        }
    }

    /// True when the search has a model and candidate `b` as the answer
    /// among `cands` would be rejected by it ([`accepted_with`]).
    fn would_reject(&self, cands: &[Candidate], b: usize) -> bool {
        match (self.decision, cands.get(b)) {
            (Some(d), Some(c)) => !accepted_with(c, self.confidence(cands, b), &d),
            _ => false,
        }
    }

    /// Goes on with a second list of candidates (the localizer's background
    /// pass) after the first ended: the best answer so far stays, the early
    /// stop starts afresh (a stop of the first list, and its coarse-score
    /// floor, say nothing about the second's scores).
    pub fn search_on(&mut self) {
        self.floor = None;
        self.confirmed = 0;
    }

    /// Finds the best candidate again among `cands` (every candidate so
    /// far), after a pass changed or appended candidates outside the
    /// search ([`crate::Localizer::corridor_pass`]).
    pub fn reselect(&mut self, cands: &[Candidate]) {
        self.best = None;
        for (i, c) in cands.iter().enumerate() {
            if c.has_pose != 0 {
                self.consider(cands, i);
            }
        }
    }

    /// Makes candidate `c` of `cands` the best when it is a better answer
    /// than the best so far ([`better`]).
    fn consider(&mut self, cands: &[Candidate], c: usize) {
        if self
            .best
            .is_none_or(|b| better(&cands[c], &cands[b], self.selection))
        {
            self.best = Some(c);
        }
    }

    /// The index of the best candidate recorded so far.
    pub fn best(&self) -> Option<usize> {
        self.best
    }

    /// True once the early stop's condition has held.
    pub fn stopping(&self) -> bool {
        self.floor.is_some()
    }

    /// Decides on the next candidate, of coarse score `gamma` and site
    /// position `site_xy` (map frame, m), given the candidates so far.
    pub fn next(&mut self, gamma: f32, site_xy: [f32; 2], cands: &[Candidate]) -> Next {
        let (Some(floor), Some(b)) = (self.floor, self.best) else {
            return Next::Examine;
        };
        if gamma < floor || self.confirmed >= CONFIRM_MAX {
            if self.would_reject(cands, b) {
                // The stop's answer, confirmed, would be rejected: the
                // place may be one of several alike (racks, rows of
                // offices) and the right one further down the list. Search
                // on; a later stop may fire again.
                self.floor = None;
                self.confirmed = 0;
                return Next::Examine;
            }
            return Next::Stop;
        }
        let (dx, dy) = (site_xy[0] - cands[b].x, site_xy[1] - cands[b].y);
        if dx * dx + dy * dy < CONFIRM_SKIP_RADIUS * CONFIRM_SKIP_RADIUS {
            return Next::Skip;
        }
        self.confirmed += 1;
        Next::Examine
    }

    /// Records candidate `c` (the last of `cands`, which holds every
    /// candidate so far) after the fine stage gave it a pose, with its
    /// coarse score `gamma`.
    pub fn record(&mut self, cands: &[Candidate], gamma: f32) {
        let Some(c) = cands.len().checked_sub(1) else {
            return;
        };
        self.consider(cands, c);
        let cand = &cands[c];
        let best_ok = self.best.is_some_and(|b| passes(&cands[b]));
        let confident = explained_ratio(cand) >= self.early_accept
            && cand.short_beams * EARLY_SHORT_SHARE <= cand.pairs
            && passes(cand);
        let enabled = self.selection == Selection::Vicinity && self.early_accept > 0.0;
        if !enabled || self.floor.is_some() {
            return;
        }
        let sure = || {
            c + 1 >= EARLY_CONFIDENCE_MIN
                && self.best.is_some_and(|b| {
                    let p = self.confidence(cands, b);
                    p >= EARLY_CONFIDENCE
                        || (c - b >= SETTLED_CANDIDATES && p >= SETTLED_CONFIDENCE)
                        || (c - b >= FIRM_CANDIDATES && p >= FIRM_CONFIDENCE)
                })
        };
        if confident || (self.early_min > 0 && c + 1 >= self.early_min && best_ok) || sure() {
            self.floor = Some(gamma - EARLY_CONFIRM_GAMMA);
        }
    }
}

/// True when another examined candidate with a pose that passes the
/// free-space check, distinct from `best` ([`distinct`]), has an evidence of
/// at least `ratio` times the best's (`ratio` 0 disables the test).
pub fn ambiguous(cands: &[Candidate], best: &Candidate, ratio: f32) -> bool {
    ratio > 0.0
        && cands.iter().any(|o| {
            o.has_pose != 0
                && o.free_space_ok != 0
                && distinct(o, best)
                && o.evidence >= ratio * best.evidence
        })
}

/// Highest confidence an ambiguous answer is given: another distinct pose
/// explains the scan nearly as well (within `ambiguity_ratio` of its
/// evidence), so the answer is at best a toss between the two.
pub const AMBIGUOUS_CONFIDENCE: f32 = 0.5;

/// The answer's confidence from the model's probability `p`: capped at
/// [`AMBIGUOUS_CONFIDENCE`] when the answer is ambiguous.
pub fn capped_confidence(p: f32, ambiguous: bool) -> f32 {
    if ambiguous {
        p.min(AMBIGUOUS_CONFIDENCE)
    } else {
        p
    }
}

/// The decision with a database's model: the best candidate has a pose and
/// its confidence (from [`capped_confidence`]) is at least the threshold.
pub fn accepted_with(best: &Candidate, confidence: f32, decision: &Decision) -> bool {
    best.has_pose != 0 && confidence >= decision.threshold
}

/// The decision in a database without a model: it passes ([`passes`]) and
/// is not ambiguous.
pub fn accepted(best: &Candidate, ambiguous: bool) -> bool {
    passes(best) && !ambiguous
}

/// Which of several maps a scan is on, from its answer on each map in
/// order (`(accepted, confidence, threshold)`: the map's decision, the
/// answer's confidence and the map's acceptance threshold; a map where it
/// could not be localized counts as not accepted with confidence 0): the
/// index of the accepted answer with the highest confidence (the earlier
/// map on a tie), provided that its probability *among the maps* is at
/// least its map's threshold too; else `None`. The rule of `mapc localize
/// A.refdb B.refdb ...` and of the Python package's `MapSet`.
///
/// The probability among the maps treats each answer's confidence `p_i` as
/// the chance that the scan is right there, the maps as exclusive: the
/// scan is on map `i` and on no other with weight `p_i prod_(j != i) (1 -
/// p_j)`, on none with weight `prod_j (1 - p_j)`, so map `i`'s probability
/// is `o_i / (1 + sum_j o_j)` with the odds `o_i = p_i / (1 - p_i)`. With
/// one map it is that map's confidence, so nothing changes; an answer
/// accepted on one map while another map also explains the scan well is
/// not (docs/results.md, "Which map am I on").
pub fn which_map<I: IntoIterator<Item = (bool, f32, f32)>>(answers: I) -> Option<usize> {
    // Confidences are capped just under 1 so the odds stay finite.
    let odds = |p: f32| {
        let p = p.clamp(0.0, 1.0 - 1e-6);
        p / (1.0 - p)
    };
    let mut best: Option<(usize, f32, f32)> = None;
    let mut total = 0.0f32;
    for (i, (accepted, confidence, threshold)) in answers.into_iter().enumerate() {
        let confidence = if confidence.is_nan() { 0.0 } else { confidence };
        total += odds(confidence);
        if accepted && best.is_none_or(|(_, c, _)| confidence.total_cmp(&c).is_gt()) {
            best = Some((i, confidence, threshold));
        }
    }
    let (i, confidence, threshold) = best?;
    (odds(confidence) / (1.0 + total) >= threshold).then_some(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_is_the_accepted_answer_with_the_highest_confidence() {
        let a = |accepted, p| (accepted, p, 0.8);
        assert_eq!(which_map([]), None);
        assert_eq!(which_map([a(false, 0.99), a(false, 0.5)]), None);
        // A higher confidence that is not accepted does not count.
        // ... but it weighs against the one that is: 0.9 against 0.99.
        assert_eq!(
            which_map([a(false, 0.99), a(true, 0.85), a(true, 0.9)]),
            None
        );
        assert_eq!(
            which_map([a(false, 0.1), a(true, 0.85), a(true, 0.999)]),
            Some(2)
        );
        // A tie goes to the earlier map (when clear of the rest).
        assert_eq!(which_map([(true, 0.999, 0.4), (true, 0.999, 0.4)]), Some(0));
        // One map: its own decision.
        assert_eq!(which_map([a(true, 0.81)]), Some(0));
        assert_eq!(which_map([a(false, 0.79)]), None);
        // Unlikely elsewhere: the accepted answer stands.
        assert_eq!(
            which_map([a(false, 0.01), a(true, 0.85), a(false, 0.02)]),
            Some(1)
        );
    }

    #[test]
    fn a_map_that_also_explains_the_scan_withholds_the_answer() {
        // Measured cases of real ACES scans on the Intel, ACES and CSAIL maps
        // (docs/results.md): accepted on a wrong map at 0.80 while the
        // others give 0.71 and 0.71, or at 0.85 while another gives 0.60.
        let a = |accepted, p| (accepted, p, 0.8);
        assert_eq!(
            which_map([a(true, 0.80), a(false, 0.71), a(false, 0.71)]),
            None
        );
        assert_eq!(
            which_map([a(false, 0.0007), a(false, 0.60), a(true, 0.85)]),
            None
        );
        // The right map of a scan that fits nowhere else keeps it.
        assert_eq!(
            which_map([a(false, 0.002), a(true, 0.82), a(false, 5e-6)]),
            Some(1)
        );
        // A confident answer against a near-miss elsewhere (similar
        // offices): 0.999 against 0.98 and 0.86 is still clear.
        assert_eq!(
            which_map([a(true, 0.999), a(true, 0.98), a(true, 0.86)]),
            Some(0)
        );
    }

    #[test]
    fn a_twin_place_as_good_caps_the_confidence_and_is_rejected() {
        let best = cand(0.0, 0.0, 0.0, 80.0, 0);
        let twin = cand(10.0, 0.0, 0.0, 79.0, 0);
        let cands = [best, twin];
        let amb = ambiguous(&cands, &best, params().select.ambiguity_ratio);
        assert!(amb);
        let mut h = [Hypothesis::default(); 5];
        let n = hypotheses(&cands, 0, Selection::Vicinity, &Decision::DEFAULT, &mut h);
        assert_eq!(n, 2);
        assert_eq!((h[0].candidate, h[1].candidate), (0, 1));
        let c = capped_confidence(h[0].confidence, amb);
        assert!(c <= AMBIGUOUS_CONFIDENCE);
        assert!(!accepted_with(&best, c, &Decision::DEFAULT));
        // Without the twin the same pose is accepted.
        let alone = [best];
        let mut h1 = [Hypothesis::default(); 5];
        hypotheses(&alone, 0, Selection::Vicinity, &Decision::DEFAULT, &mut h1);
        let c1 = capped_confidence(h1[0].confidence, ambiguous(&alone, &best, 0.97));
        assert!(accepted_with(&best, c1, &Decision::DEFAULT), "{c1}");
    }

    #[test]
    fn hypotheses_are_distinct_and_best_first() {
        // Three candidates on one pose, two on another, one on a third.
        let cands = [
            cand(0.0, 0.0, 0.0, 80.0, 0),
            cand(0.1, 0.0, 0.0, 82.0, 0),
            cand(5.0, 0.0, 0.0, 60.0, 0),
            cand(5.2, 0.1, 0.0, 61.0, 0),
            cand(0.0, 0.0, 3.0, 70.0, 0),
        ];
        let mut h = [Hypothesis::default(); 5];
        let n = hypotheses(&cands, 1, Selection::Vicinity, &Decision::DEFAULT, &mut h);
        assert_eq!(n, 3);
        // The answer first, then the best candidate of each other pose, by
        // probability.
        let mut order: Vec<u32> = h[..n].iter().map(|x| x.candidate).collect();
        assert_eq!(order[0], 1);
        order.sort_unstable();
        assert_eq!(order, [1, 3, 4]);
        assert!(h[0].confidence > h[1].confidence && h[1].confidence >= h[2].confidence);
        // A short output keeps the best ones; no pose, no hypotheses.
        let mut two = [Hypothesis::default(); 2];
        assert_eq!(
            hypotheses(&cands, 1, Selection::Vicinity, &Decision::DEFAULT, &mut two),
            2
        );
        let none = [Candidate::default()];
        assert_eq!(
            hypotheses(&none, 0, Selection::Vicinity, &Decision::DEFAULT, &mut h),
            0
        );
    }

    fn params() -> Params {
        let mut p = Params::defaults(360, 30.0);
        p.select.selection = Selection::Vicinity;
        p.select.early_accept = 0.9;
        p.select.early_min = 0;
        p
    }

    /// A candidate with a pose at (x, y, theta), evidence `e` against a
    /// threshold of 45 (20 beams), `short` of its 20 beams short.
    fn cand(x: f32, y: f32, theta: f32, e: f32, short: u32) -> Candidate {
        Candidate {
            x,
            y,
            theta,
            vicinity: e,
            evidence: e,
            vicinity_threshold: 45.0,
            pairs: 20,
            short_beams: short,
            has_pose: 1,
            free_space_ok: 1,
            ..Candidate::default()
        }
    }

    #[test]
    fn alternatives_are_listed_by_probability() {
        // The answer, then an alternative with more evidence but most of its
        // beams through walls (unlikely), then a cleaner one with less
        // evidence (likelier): the list shows the likelier one second.
        let mut through = cand(5.0, 0.0, 0.0, 75.0, 0);
        through.through_beams = 15;
        let cands = [
            cand(0.0, 0.0, 0.0, 80.0, 0),
            through,
            cand(0.0, 5.0, 0.0, 60.0, 0),
        ];
        let mut h = [Hypothesis::default(); 5];
        let n = hypotheses(&cands, 0, Selection::Vicinity, &Decision::DEFAULT, &mut h);
        assert_eq!(n, 3);
        assert_eq!(h[0].candidate, 0, "the answer stays first");
        let (p1, p2) = (h[1].confidence, h[2].confidence);
        assert!(p1 >= p2, "{p1} {p2}");
        let mut alt: Vec<u32> = h[1..n].iter().map(|x| x.candidate).collect();
        alt.sort_unstable();
        assert_eq!(alt, [1, 2], "the same alternatives, whatever their order");
        // The two orders really differ here (else the test shows nothing).
        let pt = Decision::DEFAULT.probability(&confidence::features(&cands, &cands[1]));
        let pc = Decision::DEFAULT.probability(&confidence::features(&cands, &cands[2]));
        assert!(pc > pt, "{pc} {pt}");
        assert_eq!(h[1].candidate, 2);
    }

    #[test]
    fn distinct_means_over_a_metre_or_twenty_degrees() {
        let a = cand(0.0, 0.0, 0.0, 80.0, 0);
        assert!(!distinct(&a, &cand(0.9, 0.0, 0.0, 80.0, 0)));
        assert!(distinct(&a, &cand(0.8, 0.8, 0.0, 80.0, 0)));
        assert!(!distinct(&a, &cand(0.0, 0.0, 0.34, 80.0, 0)));
        assert!(distinct(&a, &cand(0.0, 0.0, 0.35, 80.0, 0)));
        // Headings wrap: 359 degrees is 1 degree away.
        assert!(!distinct(&a, &cand(0.0, 0.0, 6.27, 80.0, 0)));
    }

    #[test]
    fn a_pose_through_walls_loses_to_one_that_is_not() {
        let good = cand(0.0, 0.0, 0.0, 50.0, 0);
        let mut through = cand(5.0, 0.0, 0.0, 89.0, 0);
        through.free_space_ok = 0;
        assert!(better(&good, &through, Selection::Vicinity));
        assert!(!better(&through, &good, Selection::Vicinity));
        // Between two that fail it, the evidence decides.
        let mut other = cand(1.0, 0.0, 0.0, 88.0, 0);
        other.free_space_ok = 0;
        assert!(better(&through, &other, Selection::Vicinity));
        let mut e = good;
        e.match_score = 2.0;
        assert!(better(&e, &good, Selection::MatchScore));
        assert!(!better(&good, &good, Selection::MatchScore));
    }

    #[test]
    fn a_twin_place_within_the_ratio_makes_the_answer_ambiguous() {
        let best = cand(0.0, 0.0, 0.0, 80.0, 0);
        let twin = cand(10.0, 0.0, 0.0, 76.0, 0);
        let near = cand(0.5, 0.0, 0.1, 79.0, 0);
        assert!(ambiguous(&[best, twin], &best, 0.9));
        assert!(!ambiguous(&[best, twin], &best, 0.96));
        assert!(!ambiguous(&[best, twin], &best, 0.0));
        // The best itself and a pose near it are no alternatives.
        assert!(!ambiguous(&[best, near], &best, 0.9));
        // Nor is a twin that sees through walls, or one with no pose.
        let mut t = twin;
        t.free_space_ok = 0;
        assert!(!ambiguous(&[best, t], &best, 0.9));
        t = twin;
        t.has_pose = 0;
        assert!(!ambiguous(&[best, t], &best, 0.9));
        assert!(accepted(&best, false));
        assert!(!accepted(&best, true));
        assert!(!accepted(&cand(0.0, 0.0, 0.0, 45.0, 0), false));
    }

    #[test]
    fn a_confident_match_stops_after_confirming_near_rivals() {
        let p = params();
        let mut s = Search::new(&p);
        let mut cands = vec![];
        // A loose first match: no stop.
        assert_eq!(s.next(0.9, [0.0, 0.0], &cands), Next::Examine);
        cands.push(cand(20.0, 0.0, 0.0, 50.0, 0));
        s.record(&cands, 0.9);
        assert!(!s.stopping());
        // A confident one (explained 85.5 / (4.5 x 19) = 1.0, one beam short).
        assert_eq!(s.next(0.88, [0.0, 0.0], &cands), Next::Examine);
        cands.push(cand(0.0, 0.0, 0.0, 85.5, 1));
        s.record(&cands, 0.88);
        assert!(s.stopping());
        assert_eq!(s.best(), Some(1));
        // Within EARLY_CONFIRM_GAMMA: a far site is examined, a near one skipped.
        assert_eq!(s.next(0.85, [10.0, 0.0], &cands), Next::Examine);
        assert_eq!(s.next(0.85, [1.0, 1.0], &cands), Next::Skip);
        // Below the floor: stop.
        assert_eq!(s.next(0.82, [10.0, 0.0], &cands), Next::Stop);
    }

    #[test]
    fn a_confident_answer_stops_after_early_confidence_min_candidates() {
        // Real-scan matches: 75 of 90 explained (0.83, under early_accept
        // 0.9), found again from every site. With the model, the search stops
        // once EARLY_CONFIDENCE_MIN candidates agree; without it, never.
        let p = params();
        let mut with = Search::new(&p).with_decision(Decision::DEFAULT);
        let mut without = Search::new(&p);
        let mut cands = vec![];
        for k in 0..EARLY_CONFIDENCE_MIN + 2 {
            cands.push(cand(0.01 * k as f32, 0.0, 0.0, 75.0, 0));
            with.record(&cands, 0.9);
            without.record(&cands, 0.9);
            assert_eq!(
                with.stopping(),
                k + 1 >= EARLY_CONFIDENCE_MIN,
                "after {}",
                k + 1
            );
            assert!(!without.stopping());
        }
        assert!(with.confidence(&cands, 0) >= EARLY_CONFIDENCE);
        assert_eq!(without.confidence(&cands, 0), 0.0);
        // After the stop the confirmation runs as after a confident match.
        assert_eq!(with.next(0.88, [30.0, 0.0], &cands), Next::Examine);
        assert_eq!(with.next(0.8, [30.0, 0.0], &cands), Next::Stop);
    }

    /// Records an answer found from four sites with the spread feature
    /// `spread` (which sets its confidence, asserted within `band`), then
    /// candidates elsewhere that see through walls (no rival): the search
    /// must stop once `wait` of them followed the best, not before.
    fn stops_after(spread: f32, band: core::ops::Range<f32>, wait: usize) {
        let p = params();
        let mut s = Search::new(&p).with_decision(Decision::DEFAULT);
        let mut cands = vec![];
        for k in 0..4 {
            let mut c = cand(0.01 * k as f32, 0.0, 0.0, 64.0, 0);
            c.spread = spread;
            cands.push(c);
            s.record(&cands, 0.9);
        }
        let p0 = s.confidence(&cands, 0);
        assert!(
            band.contains(&p0),
            "the constructed answer's confidence {p0}"
        );
        for k in 0..wait + 3 {
            cands.push(elsewhere(k));
            s.record(&cands, 0.8);
            assert!(band.contains(&s.confidence(&cands, 0)));
            let after = cands.len() - 1 - s.best().unwrap();
            assert_eq!(s.stopping(), after >= wait, "after {after}");
            if s.stopping() {
                break;
            }
        }
        assert!(s.stopping());
    }

    /// A later pose elsewhere that sees through walls, so it is no rival.
    fn elsewhere(k: usize) -> Candidate {
        Candidate {
            free_space_ok: 0,
            ..cand(10.0 + 3.0 * k as f32, 5.0, 1.0, 10.0, 10)
        }
    }

    #[test]
    fn a_settled_answer_stops_after_settled_candidates() {
        // A right-looking answer below FIRM_CONFIDENCE but above
        // SETTLED_CONFIDENCE waits SETTLED_CANDIDATES.
        stops_after(0.4, SETTLED_CONFIDENCE..FIRM_CONFIDENCE, SETTLED_CANDIDATES);
        // An answer under SETTLED_CONFIDENCE never settles.
        let p = params();
        let mut weak = Search::new(&p).with_decision(Decision::DEFAULT);
        let mut c = vec![cand(0.0, 0.0, 0.0, 30.0, 0)];
        weak.record(&c, 0.9);
        for k in 0..2 * SETTLED_CANDIDATES {
            c.push(elsewhere(k));
            weak.record(&c, 0.8);
        }
        assert!(weak.confidence(&c, 0) < SETTLED_CONFIDENCE);
        assert!(!weak.stopping());
    }

    #[test]
    fn a_firm_answer_stops_after_firm_candidates() {
        // The same answer pinned tighter (a smaller spread): at least
        // FIRM_CONFIDENCE but under EARLY_CONFIDENCE, it waits only
        // FIRM_CANDIDATES.
        stops_after(0.15, FIRM_CONFIDENCE..EARLY_CONFIDENCE, FIRM_CANDIDATES);
    }

    #[test]
    fn a_twin_keeps_the_confidence_stop_from_firing() {
        let p = params();
        let mut s = Search::new(&p).with_decision(Decision::DEFAULT);
        let mut cands = vec![cand(10.0, 0.0, 0.0, 74.0, 0)];
        s.record(&cands, 0.9);
        for k in 0..2 * EARLY_CONFIDENCE_MIN {
            cands.push(cand(0.01 * k as f32, 0.0, 0.0, 75.0, 0));
            s.record(&cands, 0.9);
        }
        let best = s.best().unwrap();
        assert!(s.confidence(&cands, best) <= AMBIGUOUS_CONFIDENCE);
        assert!(
            !s.stopping(),
            "an ambiguous answer must not stop the search"
        );
        // Nor does it fire with the early stop switched off.
        let mut off = params();
        off.select.early_accept = 0.0;
        let mut s = Search::new(&off).with_decision(Decision::DEFAULT);
        let mut c = vec![];
        for k in 0..2 * EARLY_CONFIDENCE_MIN {
            c.push(cand(0.01 * k as f32, 0.0, 0.0, 75.0, 0));
            s.record(&c, 0.9);
        }
        assert!(!s.stopping());
    }

    #[test]
    fn a_stop_whose_answer_the_model_rejects_searches_on() {
        // A confident match (one beam short), then a twin as good among the
        // rivals the confirmation examines: the answer is ambiguous, so
        // the model rejects it, and the search goes on below the floor (the
        // right place may be further down the list) instead of stopping.
        let p = params();
        let mut with = Search::new(&p).with_decision(Decision::DEFAULT);
        let mut without = Search::new(&p);
        let mut cands = vec![cand(0.0, 0.0, 0.0, 77.0, 1)];
        with.record(&cands, 0.9);
        without.record(&cands, 0.9);
        assert!(with.stopping() && without.stopping());
        assert_eq!(with.next(0.88, [10.0, 0.0], &cands), Next::Examine);
        assert_eq!(without.next(0.88, [10.0, 0.0], &cands), Next::Examine);
        cands.push(cand(10.0, 0.0, 0.0, 76.5, 1));
        with.record(&cands, 0.88);
        without.record(&cands, 0.88);
        assert!(with.confidence(&cands, 0) <= AMBIGUOUS_CONFIDENCE);
        assert_eq!(with.next(0.8, [30.0, 0.0], &cands), Next::Examine);
        assert!(!with.stopping());
        // Without a model the stop stands.
        assert_eq!(without.next(0.8, [30.0, 0.0], &cands), Next::Stop);
        // A later confident match that explains far more, pinned by walls
        // all round and found from four sites, stops it again, for good.
        for k in 0..4 {
            let mut pinned = cand(30.0 + 0.01 * k as f32, 0.0, 0.0, 90.0, 0);
            pinned.spread = 0.15;
            cands.push(pinned);
            with.record(&cands, 0.8);
        }
        assert!(with.stopping());
        assert_eq!(with.best(), Some(2));
        let p2 = with.confidence(&cands, 2);
        assert!(p2 >= Decision::DEFAULT.threshold, "{p2}");
        assert_eq!(with.next(0.7, [40.0, 0.0], &cands), Next::Stop);
    }

    #[test]
    fn confirmation_examines_at_most_confirm_max_rivals() {
        let mut s = Search::new(&params());
        let cands = vec![cand(0.0, 0.0, 0.0, 90.0, 0)];
        s.record(&cands, 0.9);
        for _ in 0..CONFIRM_MAX {
            assert_eq!(s.next(0.9, [30.0, 0.0], &cands), Next::Examine);
        }
        assert_eq!(s.next(0.9, [30.0, 0.0], &cands), Next::Stop);
    }

    #[test]
    fn many_short_beams_or_no_early_accept_do_not_stop() {
        let mut s = Search::new(&params());
        // 5 of 20 beams short: more than a fifth.
        let c = vec![cand(0.0, 0.0, 0.0, 67.5, 5)];
        s.record(&c, 0.9);
        assert!(!s.stopping());
        let mut p = params();
        p.select.early_accept = 0.0;
        let mut s = Search::new(&p);
        s.record(&[cand(0.0, 0.0, 0.0, 90.0, 0)], 0.9);
        assert!(!s.stopping());
        p.select.early_accept = 0.9;
        p.select.selection = Selection::MatchScore;
        let mut s = Search::new(&p);
        s.record(&[cand(0.0, 0.0, 0.0, 90.0, 0)], 0.9);
        assert!(!s.stopping());
    }

    #[test]
    fn an_exhaustive_search_never_stops_and_search_on_starts_afresh() {
        // The confident match of `a_confident_match_stops_after_confirming_near_rivals`
        // and agreeing matches that reach the confidence stop: an exhaustive
        // search (a short-reach scan) examines on.
        let p = params();
        let mut s = Search::new(&p)
            .with_decision(Decision::DEFAULT)
            .exhaustive();
        let mut cands = vec![];
        for k in 0..EARLY_CONFIDENCE_MIN + 25 {
            let g = 0.9 - 0.001 * k as f32;
            assert_eq!(s.next(g, [10.0 * k as f32, 0.0], &cands), Next::Examine);
            cands.push(cand(0.0, 0.0, 0.0, 85.5, 1));
            s.record(&cands, g);
            assert!(!s.stopping(), "stopped at {k}");
        }
        assert_eq!(s.best(), Some(0));
        // A stopping search, told to search on (the background pass):
        // examines again, keeps its best answer.
        let mut s = Search::new(&p);
        let mut cands = vec![cand(0.0, 0.0, 0.0, 85.5, 1)];
        s.record(&cands, 0.9);
        assert!(s.stopping());
        assert_eq!(s.next(0.5, [10.0, 0.0], &cands), Next::Stop);
        s.search_on();
        assert!(!s.stopping());
        assert_eq!(s.next(0.5, [10.0, 0.0], &cands), Next::Examine);
        cands.push(cand(20.0, 0.0, 0.0, 60.0, 0));
        s.record(&cands, 0.5);
        assert_eq!(s.best(), Some(0));
    }

    #[test]
    fn early_min_stops_once_enough_candidates_and_a_passing_best() {
        let mut p = params();
        p.select.early_accept = 0.99;
        p.select.early_min = 3;
        let mut s = Search::new(&p);
        let mut cands = vec![];
        for k in 0..3 {
            cands.push(cand(k as f32 * 10.0, 0.0, 0.0, 60.0, 4));
            s.record(&cands, 0.9);
            assert_eq!(s.stopping(), k == 2, "after {} candidates", k + 1);
        }
    }

    #[test]
    fn a_pose_found_after_the_search_is_placed_without_merging_places() {
        // Three places: the answer at the origin, a rival 1.8 m along the
        // corridor, another 10 m away turned end for end.
        let cands = [
            cand(0.0, 0.0, 0.0, 60.0, 0),
            cand(1.8, 0.0, 0.0, 55.0, 0),
            Candidate {
                has_pose: 0,
                ..cand(20.0, 0.0, 0.0, 0.0, 0)
            },
            cand(10.0, 0.0, 3.1, 50.0, 0),
        ];
        // A new place (the candidate without a pose does not count).
        let new = cand(20.0, 0.0, 0.0, 70.0, 0);
        assert_eq!(placement(&cands, &new), Placement::New);
        // A better fit of the rival's place: it replaces the rival's pose.
        let refit = cand(2.2, 0.1, 0.05, 58.0, 0);
        assert_eq!(placement(&cands, &refit), Placement::Refits(1));
        // A fit of a place no better than the candidate there adds nothing.
        let worse = cand(2.2, 0.1, 0.05, 55.0, 0);
        assert_eq!(placement(&cands, &worse), Placement::Known);
        // The other place turned back by more than 20 degrees is a new one.
        let turned = cand(10.0, 0.0, 0.0, 52.0, 0);
        assert_eq!(placement(&cands, &turned), Placement::New);
        // A pose within 1 m of both the answer and the rival would merge
        // two places the candidates keep apart, however well it fits.
        let between = cand(0.9, 0.0, 0.0, 65.0, 0);
        assert_eq!(placement(&cands, &between), Placement::Known);
        // Between two candidates of one place, the one with more evidence
        // is refitted.
        let pair = [cand(0.0, 0.0, 0.0, 40.0, 0), cand(0.3, 0.0, 0.0, 45.0, 0)];
        let better = cand(0.2, 0.0, 0.0, 50.0, 0);
        assert_eq!(placement(&pair, &better), Placement::Refits(1));
    }

    #[test]
    fn reselect_finds_the_best_among_changed_candidates() {
        let p = params();
        let mut s = Search::new(&p);
        let mut cands = vec![cand(0.0, 0.0, 0.0, 60.0, 0)];
        s.record(&cands, 0.9);
        cands.push(cand(5.0, 0.0, 0.0, 50.0, 0));
        s.record(&cands, 0.8);
        assert_eq!(s.best(), Some(0));
        // The second candidate refitted with more evidence, and a third
        // appended that fails the free-space check with still more.
        cands[1].evidence = 70.0;
        let mut through = cand(9.0, 0.0, 0.0, 80.0, 0);
        through.free_space_ok = 0;
        cands.push(through);
        s.reselect(&cands);
        assert_eq!(s.best(), Some(1));
    }
}
