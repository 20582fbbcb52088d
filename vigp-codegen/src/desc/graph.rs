//! The joint graph of a description: the spanning tree grown from the
//! world (minimal coordinates) and the joints left over, which close loops
//! (constraints).

use super::model::Joint;

/// The spanning tree from the world: joints in declaration order, each
/// placing its child when its parent is placed.
pub struct Tree {
    /// For each link, the joint that places it.
    pub placed_by: Vec<Option<usize>>,
    /// Per joint: does it place a link?
    pub is_tree: Vec<bool>,
    /// Tree joints in placement order.
    pub placement: Vec<usize>,
    /// Links in placement order.
    pub order: Vec<usize>,
}

impl Tree {
    /// Grow the tree over `joints` among `links` links.
    pub fn grow<K, A, const D: usize>(joints: &[Joint<K, A, D>], links: usize) -> Tree {
        let mut t = Tree {
            placed_by: vec![None; links],
            is_tree: vec![false; joints.len()],
            placement: Vec::new(),
            order: Vec::new(),
        };
        loop {
            let mut progress = false;
            for (j, joint) in joints.iter().enumerate() {
                if t.is_tree[j] {
                    continue;
                }
                let parent_ready = joint.parent.link().is_none_or(|l| t.placed_by[l].is_some());
                if let Some(c) = joint.child.link()
                    && parent_ready
                    && t.placed_by[c].is_none()
                {
                    t.placed_by[c] = Some(j);
                    t.is_tree[j] = true;
                    t.placement.push(j);
                    t.order.push(c);
                    progress = true;
                }
            }
            if !progress {
                return t;
            }
        }
    }
}
