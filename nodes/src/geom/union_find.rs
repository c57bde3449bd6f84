//! Union-find over dense indices. Each set is named by its smallest member, so the names do not
//! depend on the order the joins come in (charts, flat faces and blocks come out the same at any
//! thread count and in any edge order).

/// Disjoint sets over `0..n`.
pub struct UnionFind(Vec<u32>);

impl UnionFind {
    /// `n` sets of one.
    pub fn new(n: usize) -> UnionFind {
        UnionFind((0..n as u32).collect())
    }

    /// The name of `x`'s set: its smallest member.
    pub fn root(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let up = self.0[self.0[x as usize] as usize];
            self.0[x as usize] = up;
            x = up;
        }
        x
    }

    /// Joins the sets of `a` and `b`.
    pub fn join(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.root(a), self.root(b));
        self.0[ra.max(rb) as usize] = ra.min(rb);
    }

    /// Every member's set, by name.
    pub fn names(mut self) -> Vec<u32> {
        (0..self.0.len() as u32).map(|x| self.root(x)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_are_named_by_their_smallest_member_whatever_the_join_order() {
        let mut u = UnionFind::new(6);
        u.join(5, 3);
        u.join(3, 4);
        u.join(1, 2);
        u.join(4, 2);
        assert_eq!(u.names(), vec![0, 1, 1, 1, 1, 1]);
    }
}
