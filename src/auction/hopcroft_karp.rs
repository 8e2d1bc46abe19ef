//! Hopcroft–Karp maximum-cardinality matching on a CSR pattern: the feasibility check before
//! the auction.
use super::NONE;

/// Maximum matching on a valid CSR pattern; returns (size, row mate with NONE = free).
pub(super) fn hopcroft_karp(nr: usize, nc: usize, ptr: &[usize], idx: &[u32]) -> (usize, Vec<u32>) {
    const INF: u32 = u32::MAX;
    let mut rm = vec![NONE; nr];
    let mut cm = vec![NONE; nc];
    let mut size = 0usize;
    // Greedy start, each row trying first the column proportional to its own index (found by
    // bisection, meaningful when rows are sorted): on near-diagonal patterns that column is
    // almost always still free and the greedy matching is already perfect.
    for (r, mate) in rm.iter_mut().enumerate() {
        let row = &idx[ptr[r]..ptr[r + 1]];
        let target = ((r as u128 * nc as u128) / nr.max(1) as u128) as u32;
        let h = row.partition_point(|&c| c < target);
        if let Some(&c) = row[h..]
            .iter()
            .chain(&row[..h])
            .find(|&&c| cm[c as usize] == NONE)
        {
            *mate = c;
            cm[c as usize] = r as u32;
            size += 1;
        }
    }
    let target = nr.min(nc);
    if size == target {
        return (size, rm);
    }
    let mut dist = vec![INF; nr];
    let mut queue: Vec<u32> = Vec::with_capacity(nr);
    let mut it = vec![0usize; nr];
    let mut stack: Vec<u32> = Vec::new();
    loop {
        queue.clear();
        for r in 0..nr {
            if rm[r] == NONE {
                dist[r] = 0;
                queue.push(r as u32);
            } else {
                dist[r] = INF;
            }
        }
        let mut limit = INF;
        let mut head = 0;
        while head < queue.len() {
            let r = queue[head] as usize;
            head += 1;
            let dr = dist[r];
            if dr >= limit {
                break;
            }
            for &c in &idx[ptr[r]..ptr[r + 1]] {
                let r2 = cm[c as usize];
                if r2 == NONE {
                    if limit == INF {
                        limit = dr + 1;
                    }
                } else if dist[r2 as usize] == INF {
                    dist[r2 as usize] = dr + 1;
                    queue.push(r2);
                }
            }
        }
        if limit == INF {
            break;
        }
        it.copy_from_slice(&ptr[..nr]);
        let mut aug = 0usize;
        for r0 in 0..nr {
            if rm[r0] != NONE || dist[r0] != 0 {
                continue;
            }
            stack.clear();
            stack.push(r0 as u32);
            while let Some(&top) = stack.last() {
                let r = top as usize;
                if it[r] < ptr[r + 1] {
                    let c = idx[it[r]];
                    it[r] += 1;
                    let r2 = cm[c as usize];
                    let d = dist[r] + 1;
                    if r2 == NONE {
                        if d == limit {
                            // Flip the path: each row takes the column its successor held.
                            let mut c = c;
                            for &rr in stack.iter().rev() {
                                let prev = rm[rr as usize];
                                rm[rr as usize] = c;
                                cm[c as usize] = rr;
                                c = prev;
                            }
                            aug += 1;
                            break;
                        }
                    } else if d < limit && dist[r2 as usize] == d {
                        stack.push(r2);
                    }
                } else {
                    dist[r] = INF;
                    stack.pop();
                }
            }
        }
        size += aug;
        if aug == 0 || size == target {
            break;
        }
    }
    (size, rm)
}
