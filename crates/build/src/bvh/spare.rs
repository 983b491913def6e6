//! Arrays kept from one build to the next ([`Spare`]).

use crate::bvh::binary::PrimRef;
use crate::bvh::NodeB;

/// Arrays of one kind kept from one build to the next, emptied: the builder's largest
/// (references, 8-wide nodes, primitive order: about 70 bytes per primitive). Parts of a
/// model are built one after another and benchmarks repeat builds, and fresh memory costs a
/// page fault per 4 KiB when first written (docs/PERF.md, "Spare arrays"). At most
/// [`Spare::new`]'s `keep` arrays of a kind are kept (one per build running at once). The
/// price: a part's references stay allocated through its tile stage instead of being freed
/// before it, 32 bytes per triangle more at the peak, within the
/// [`crate::INCORE_BYTES_PER_TRI`] a part is budgeted.
pub(crate) struct Spare<T> {
    kept: std::sync::Mutex<Vec<Vec<T>>>,
    keep: usize,
}

pub(crate) static SPARE_REFS: Spare<PrimRef> = Spare::new(8);
pub(crate) static SPARE_NODES: Spare<NodeB> = Spare::new(8);
pub(crate) static SPARE_ORDER: Spare<u32> = Spare::new(8);

impl<T> Spare<T> {
    /// Keeping at most `keep` arrays.
    pub(crate) const fn new(keep: usize) -> Spare<T> {
        Spare { kept: std::sync::Mutex::new(Vec::new()), keep }
    }

    /// An empty array, with the capacity of an earlier build's when one was kept.
    pub(crate) fn take(&self) -> Vec<T> {
        self.kept.lock().unwrap_or_else(|p| p.into_inner()).pop().unwrap_or_default()
    }

    /// Frees every kept array.
    pub(crate) fn clear(&self) {
        std::mem::take(&mut *self.kept.lock().unwrap_or_else(|p| p.into_inner()));
    }

    pub(crate) fn give(&self, mut v: Vec<T>) {
        v.clear();
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        if v.capacity() > 0 && kept.len() < self.keep {
            kept.push(v);
        }
    }
}
