//! Disjoint sets over `0..n` (union by size, path halving): the connected components of clustering and of
//! merging clusters that belong to one object.

pub(crate) struct UnionFind {
    parent: Vec<usize>,
    size: Vec<usize>,
}

impl UnionFind {
    pub(crate) fn new(count: usize) -> Self {
        Self { parent: (0..count).collect(), size: vec![1; count] }
    }

    pub(crate) fn find(&mut self, mut item: usize) -> usize {
        while self.parent[item] != item {
            self.parent[item] = self.parent[self.parent[item]];
            item = self.parent[item];
        }
        item
    }

    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a;
        self.size[a] += self.size[b];
    }

    /// Each item's set as a dense label `0..sets`, numbered in order of first appearance.
    pub(crate) fn labels(&mut self) -> (Vec<usize>, usize) {
        let mut dense = vec![usize::MAX; self.parent.len()];
        let mut sets = 0;
        let labels = (0..self.parent.len())
            .map(|item| {
                let root = self.find(item);
                if dense[root] == usize::MAX {
                    dense[root] = sets;
                    sets += 1;
                }
                dense[root]
            })
            .collect();
        (labels, sets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unions_form_dense_labels_in_order_of_appearance() {
        let mut sets = UnionFind::new(6);
        sets.union(4, 1);
        sets.union(5, 3);
        sets.union(3, 4);
        assert_eq!(sets.labels(), (vec![0, 1, 2, 1, 1, 1], 3));
    }
}
