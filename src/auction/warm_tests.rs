//! Tests of the warm-started solver: optimum and duals against the dense Hungarian reference
//! over chains of perturbed costs (ties, sparse and infeasible patterns, rectangular), the
//! uniqueness flag against exhaustive enumeration, fallbacks and malformed input.
use super::tests::{random_dense, reference_int, to_csr, Dense, Rng};
use super::*;
use crate::csr::Csr;

fn total(d: &Dense<i64>, assign: &[i64]) -> i128 {
    assign
        .iter()
        .enumerate()
        .map(|(r, &c)| d[r][c as usize].expect("assigned pair is stored") as i128)
        .sum()
}

/// Number of optimal assignments of every row (n_rows <= n_cols), by enumeration.
fn count_optima(d: &Dense<i64>, nc: usize) -> (i128, usize) {
    fn go(d: &Dense<i64>, r: usize, used: &mut Vec<bool>, acc: i128, best: &mut (i128, usize)) {
        if r == d.len() {
            if acc > best.0 {
                *best = (acc, 1);
            } else if acc == best.0 {
                best.1 += 1;
            }
            return;
        }
        for c in 0..used.len() {
            if let (false, Some(x)) = (used[c], d[r][c]) {
                used[c] = true;
                go(d, r + 1, used, acc + x as i128, best);
                used[c] = false;
            }
        }
    }
    let mut best = (i128::MIN, 0);
    go(d, 0, &mut vec![false; nc], 0, &mut best);
    best
}

/// The solution is a full one-to-one assignment in the pattern and the prices, with the row
/// potentials they imply, are optimal duals.
fn check_duals(csr: &Csr<i64>, s: &WarmSolution) {
    let v = csr.view();
    let mut used = vec![false; v.n_cols];
    for (r, &c) in s.assign.iter().enumerate() {
        assert!(c >= 0 && !used[c as usize], "row {r}");
        used[c as usize] = true;
        let row = v.row(r);
        let vals = v.row_data(r);
        let own = row.iter().position(|&j| j as i64 == c).expect("in pattern");
        let u = vals[own] - s.prices[c as usize];
        for (k, &j) in row.iter().enumerate() {
            assert!(
                u + s.prices[j as usize] >= vals[k],
                "dual infeasible at ({r}, {j})"
            );
        }
    }
    for (j, &p) in s.prices.iter().enumerate() {
        assert!(p >= 0);
        if !used[j] {
            assert_eq!(p, 0, "free column {j} must have price 0");
        }
    }
}

/// `d` with about `share` of its stored entries moved by up to `step` (some dropped or added).
fn perturb(rng: &mut Rng, d: &Dense<i64>, share: f64, step: i64) -> Dense<i64> {
    d.iter()
        .map(|row| {
            row.iter()
                .map(|&x| {
                    if rng.unit() >= share {
                        return x;
                    }
                    match (x, rng.below(6)) {
                        (Some(_), 0) => None,
                        (None, 1) => Some(rng.range(0, 3 * step)),
                        (Some(x), _) => Some(x + rng.range(-step, step)),
                        (None, _) => None,
                    }
                })
                .collect()
        })
        .collect()
}

#[test]
fn chains_of_perturbed_costs_stay_optimal() {
    let mut rng = Rng(0x2545f4914f6cdd1d);
    let (mut solved, mut warm_used, mut unique_seen, mut tie_seen) = (0, 0, 0, 0);
    for t in 0..1500 {
        let nr = 1 + rng.below(7) as usize;
        let nc = nr + [0, 0, 1, 3][t % 4];
        let density = [1.0, 0.7, 0.45][(t / 4) % 3];
        let hi = [2, 12, 400][(t / 12) % 3];
        let mut d = random_dense(&mut rng, nr, nc, density, |r| r.range(0, hi));
        let mut prev = vec![-1i64; nr];
        let mut prices = vec![0i64; nc];
        for _ in 0..4 {
            let csr = to_csr(&d, nc, Some(&mut rng));
            let (forbidden, opt) = reference_int(&d, nc, true);
            let got = warm_assignment(&csr.view(), &prev, &prices, nr).unwrap();
            if forbidden > 0 {
                assert!(got.is_none(), "infeasible pattern must fall back");
            } else {
                let s = got.expect("a feasible problem is solved within max_repair = n");
                assert_eq!(total(&d, &s.assign), opt, "t={t}");
                check_duals(&csr, &s);
                let (best, n_opt) = count_optima(&d, nc);
                assert_eq!(best, opt);
                assert_eq!(s.unique, n_opt == 1, "t={t}: {n_opt} optima");
                if s.unique {
                    unique_seen += 1;
                    let auction = auction_assignment_int(&csr.view(), true).unwrap();
                    assert_eq!(
                        auction, s.assign,
                        "a unique optimum is every solver's answer"
                    );
                } else {
                    tie_seen += 1;
                }
                if s.repaired < nr {
                    warm_used += 1;
                }
                solved += 1;
                prev = s.assign;
                prices = s.prices;
            }
            d = perturb(&mut rng, &d, 0.25, hi / 4 + 1);
        }
    }
    assert!(solved > 3000 && warm_used > 1000, "{solved} {warm_used}");
    assert!(
        unique_seen > 500 && tie_seen > 500,
        "{unique_seen} {tie_seen}"
    );
}

#[test]
fn medium_sparse_chains_match_the_reference() {
    let mut rng = Rng(77);
    for t in 0..120 {
        let nr = 20 + rng.below(60) as usize;
        let nc = nr + [0, 5][t % 2];
        let mut d = random_dense(&mut rng, nr, nc, 0.15, |r| r.range(0, 40));
        // A stored diagonal keeps every cost feasible, like HOPE's `keep` column.
        let keep = |d: &mut Dense<i64>, rng: &mut Rng| {
            for (r, row) in d.iter_mut().enumerate() {
                row[r].get_or_insert_with(|| rng.range(0, 40));
            }
        };
        keep(&mut d, &mut rng);
        let mut prev: Vec<i64> = (0..nr as i64).collect();
        let mut prices = vec![0i64; nc];
        for step in 0..5 {
            let csr = to_csr(&d, nc, None);
            let (_, opt) = reference_int(&d, nc, true);
            let s = warm_assignment(&csr.view(), &prev, &prices, nr)
                .unwrap()
                .unwrap();
            assert_eq!(total(&d, &s.assign), opt, "t={t} step={step}");
            check_duals(&csr, &s);
            prev = s.assign;
            prices = s.prices;
            d = perturb(&mut rng, &d, 0.05, 10);
            keep(&mut d, &mut rng);
        }
    }
}

#[test]
fn an_unchanged_cost_repairs_nothing() {
    let mut rng = Rng(5);
    let d = random_dense(&mut rng, 30, 34, 0.3, |r| r.range(0, 9));
    let mut d = d;
    for (r, row) in d.iter_mut().enumerate() {
        row[r].get_or_insert(0);
    }
    let csr = to_csr(&d, 34, None);
    let first = warm_assignment(&csr.view(), &[-1; 30], &[0; 34], 30)
        .unwrap()
        .unwrap();
    let again = warm_assignment(&csr.view(), &first.assign, &first.prices, 0)
        .unwrap()
        .expect("nothing breaks");
    assert_eq!(again.repaired, 0);
    assert_eq!(again.assign, first.assign);
    assert_eq!(again.prices, first.prices);
}

#[test]
fn too_many_broken_rows_fall_back() {
    // Both rows prefer the other's column now.
    let c = Csr {
        n_rows: 2,
        n_cols: 2,
        indptr: vec![0, 2, 4],
        indices: vec![0, 1, 0, 1],
        data: vec![0i64, 5, 5, 0],
    };
    assert_eq!(
        warm_assignment(&c.view(), &[0, 1], &[0, 0], 1).unwrap(),
        None
    );
    let s = warm_assignment(&c.view(), &[0, 1], &[0, 0], 2)
        .unwrap()
        .unwrap();
    assert_eq!(s.assign, vec![1, 0]);
    assert_eq!(s.repaired, 2);
    assert!(s.unique);
}

#[test]
fn unsupported_shapes_and_values_fall_back() {
    let tall = Csr {
        n_rows: 2,
        n_cols: 1,
        indptr: vec![0, 1, 2],
        indices: vec![0, 0],
        data: vec![1i64, 2],
    };
    assert_eq!(
        warm_assignment(&tall.view(), &[0, -1], &[0], 2).unwrap(),
        None
    );
    let huge = Csr {
        n_rows: 1,
        n_cols: 1,
        indptr: vec![0, 1],
        indices: vec![0],
        data: vec![1i64 << 40],
    };
    assert_eq!(warm_assignment(&huge.view(), &[0], &[0], 1).unwrap(), None);
}

#[test]
fn malformed_input_is_an_error() {
    let c = Csr {
        n_rows: 2,
        n_cols: 2,
        indptr: vec![0, 1, 2],
        indices: vec![0, 1],
        data: vec![1i64, 1],
    };
    assert!(warm_assignment(&c.view(), &[0], &[0, 0], 2).is_err());
    assert!(warm_assignment(&c.view(), &[0, 1], &[0], 2).is_err());
    assert!(warm_assignment(&c.view(), &[0, 1], &[0, -1], 2).is_err());
    let bad = Csr {
        n_rows: 2,
        n_cols: 2,
        indptr: vec![0, 1, 5],
        indices: vec![0, 1],
        data: vec![1i64, 1],
    };
    assert!(warm_assignment(&bad.view(), &[0, 1], &[0, 0], 2).is_err());
    let dup = Csr {
        n_rows: 1,
        n_cols: 2,
        indptr: vec![0, 2],
        indices: vec![1, 1],
        data: vec![1i64, 1],
    };
    assert!(warm_assignment(&dup.view(), &[1], &[0, 0], 1).is_err());
}
