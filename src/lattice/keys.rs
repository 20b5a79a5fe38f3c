//! Lattice vertices and their numbering: packed 16-bit-lane keys, the hash table from key to vertex id, and the
//! block-parallel numbering of all pixels' simplex vertices by first appearance in raster order (so ids, and
//! every filter result, do not depend on the thread count).

use super::embed::{Embedding, Features, LANES};
use super::*;

/// Ids, weights and keys of the simplex vertices of all pixels, numbered by first appearance in raster order:
/// per-entry ids and barycentric weights (`[pixel·D1 + k]`), the keys in id order, and the table from key to
/// id.
///
/// Blocks of pixels are embedded and numbered in parallel, each with its own table, and the blocks' keys are
/// then merged in block order into one table; a key's global id is thus its first appearance in the whole
/// raster, exactly as in one sequential pass, whatever the number of blocks or threads.
pub(super) fn assign_vertex_ids(features: Features<'_>) -> (Vec<u32>, Vec<f32>, KeyTable) {
    let block = features.len().div_ceil(rayon::current_num_threads().max(1)).max(16_384);
    assign_vertex_ids_in_blocks(features, block)
}

/// [`assign_vertex_ids`] with a given block size in pixels.
pub(super) fn assign_vertex_ids_in_blocks(features: Features<'_>, block: usize) -> (Vec<u32>, Vec<f32>, KeyTable) {
    let npix = features.len();
    let block = block.max(1);
    let mut pix_vertex = vec![0u32; npix * D1];
    let mut pix_weight = vec![0.0f32; npix * D1];
    // Per block: local ids into pix_vertex, and the block's table of keys in local id order. The first block's
    // table becomes the global one (its ids already are global), so it gets room for the whole image (about 0.4
    // vertices per pixel on natural images; a table grows if there are more).
    let mut tables: Vec<KeyTable> = pix_vertex
        .par_chunks_mut(block * D1)
        .zip(pix_weight.par_chunks_mut(block * D1))
        .enumerate()
        .map(|(b, (ids, weights))| {
            let expected = if b == 0 { npix } else { ids.len() / D1 } / 2;
            number_block(features, b * block, ids, weights, expected, npix * D1)
        })
        .collect();
    if tables.is_empty() {
        return (pix_vertex, pix_weight, KeyTable::with_capacity(0, 0));
    }
    let rest = tables.split_off(1);
    let mut table = tables.pop().expect("the first block's table");
    let maps: Vec<Vec<u32>> = rest.iter().map(|t| t.keys.iter().map(|key| table.insert(key)).collect()).collect();
    pix_vertex.par_chunks_mut(block * D1).skip(1).zip(maps.par_iter()).for_each(|(ids, map)| {
        ids.iter_mut().for_each(|id| *id = map[*id as usize]);
    });
    (pix_vertex, pix_weight, table)
}

/// Embeds the pixels `first..` (as many as `ids` has room for) and numbers their vertices by first appearance
/// (ids into `ids`, barycentric weights into `weights`), returning the block's table (sized for `expected`
/// keys, it grows if there are more; ids below `max_keys`, the whole image's bound, as it may become the global
/// table), its keys in id order. Compiled for
/// AVX2 + FMA as well, where the embedding's rounding is one instruction instead of a libm call (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
pub(super) fn number_block<'f>(
    features: Features<'f>,
    first: usize,
    ids: &mut [u32],
    weights: &mut [f32],
    expected: usize,
    max_keys: usize,
) -> KeyTable {
    let mut table = KeyTable::with_capacity(expected, max_keys);
    // Horizontally adjacent pixels often lie in the same simplex (then they share all ids) and otherwise share
    // some of its vertices: a vertex can only equal the previous pixel's vertex of the same remainder, so
    // compare with that one (one comparison) and probe the table only on a miss. Same ids as probing every key.
    let mut prev: Option<(Embedding, [Key; D1], [u32; D1])> = None;
    let npix = ids.len() / D1;
    let mut batch = [Embedding::default(); LANES];
    for (k, (ids, wts)) in ids.chunks_exact_mut(D1).zip(weights.chunks_exact_mut(D1)).enumerate() {
        if k % LANES == 0 {
            batch = features.lanes_at(first + k, (npix - k).min(LANES));
        }
        let e = batch[k % LANES];
        wts.copy_from_slice(&e.weights);
        if let Some((pe, pkeys, pids)) = &mut prev {
            if pe.origin == e.origin && pe.rank == e.rank {
                ids.copy_from_slice(pids);
                continue;
            }
            for (rem, (id, (pkey, pid))) in ids.iter_mut().zip(pkeys.iter_mut().zip(pids.iter_mut())).enumerate() {
                let key = e.key(rem);
                if key != *pkey {
                    *pkey = key;
                    *pid = table.insert(&key);
                }
                *id = *pid;
            }
            *pe = e;
        } else {
            let keys: [Key; D1] = std::array::from_fn(|rem| e.key(rem));
            for (id, key) in ids.iter_mut().zip(&keys) {
                *id = table.insert(key);
            }
            let mut own = [0u32; D1];
            own.copy_from_slice(ids);
            prev = Some((e, keys, own));
        }
    }
    table
}

/// A lattice vertex: its first d coordinates (the d+1-th is minus their sum), each stored biased by 2¹⁵ in a
/// 16-bit lane, lanes 0–3 in `lo` and lane 4 in `hi`. Built and compared in registers; the bias keeps every lane
/// away from wrapping, so a blur step is one add per word (see [`MAX_FEATURE`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, packed)]
pub(super) struct Key {
    lo: u64,
    hi: u16,
}

pub(super) const KEY_BIAS: i32 = 1 << 15;

impl Embedding {
    /// The key of the simplex vertex with remainder `rem`: the origin plus the canonical offset `rem` for the
    /// coordinates ranked within the first d+1−rem, `rem` − (d+1) for the others. The d+1-th coordinate is
    /// implied by the zero sum and left out.
    #[inline(always)]
    pub(super) fn key(&self, rem: usize) -> Key {
        Key::from_coords(std::array::from_fn(|i| {
            let offset = if self.rank[i] as usize <= D - rem { rem as i32 } else { rem as i32 - D1 as i32 };
            self.origin[i] + offset
        }))
    }

    /// All d+1 vertex keys, by remainder.
    #[cfg(test)]
    pub(super) fn keys(&self) -> [Key; D1] {
        std::array::from_fn(|rem| self.key(rem))
    }
}

impl Key {
    /// The key of lattice coordinates `c` (the first d).
    ///
    /// # Panics
    /// If a coordinate does not fit 16 bits (prevented by [`features_fit`]).
    #[inline(always)]
    pub(super) fn from_coords(c: [i32; D]) -> Key {
        let lane = |v: i32| u16::try_from(v + KEY_BIAS).expect("lattice coordinate overflows 16 bits");
        let lo = (0..4).fold(0u64, |lo, i| lo | u64::from(lane(c[i])) << (16 * i));
        Key { lo, hi: lane(c[4]) }
    }

    /// The lattice coordinates.
    #[cfg(test)]
    pub(super) fn coords(&self) -> [i32; D] {
        let Key { lo, hi } = *self;
        std::array::from_fn(|i| if i < 4 { (lo >> (16 * i)) as u16 } else { hi } as i32 - KEY_BIAS)
    }

    /// The neighbour one blur step along lattice direction `dir` (0..=d), up or down: ±((1, …, 1) − (d+1)·e_dir)
    /// (for dir = d the moved coordinate is the implied one, so only the all-ones part shows).
    #[inline(always)]
    pub(super) fn step(&self, dir: usize, up: bool) -> Key {
        let Key { lo, hi } = *self;
        let moved = |c: usize| {
            let lane = if c < 4 { (lo >> (16 * c)) as u16 } else { hi };
            let offset = 1 - if c == dir { D1 as i16 } else { 0 };
            lane.wrapping_add((if up { offset } else { -offset }) as u16)
        };
        Key { lo: (0..4).fold(0u64, |w, c| w | u64::from(moved(c)) << (16 * c)), hi: moved(4) }
    }
}

/// Open-addressing hash table from lattice keys to vertex ids, numbering new keys in insertion order (linear
/// probing, power-of-two capacity). A slot is 4 bytes: the id in the low bits (as many as the largest possible
/// id needs) and the top bits of the key's hash above it, so the table stays small enough for the L2 cache and a
/// probe reads the stored key (`keys[id]`, usually cached: ids follow the raster) only when those bits match.
pub(super) struct KeyTable {
    /// `hash_bits | id`, or `EMPTY`.
    pub(super) slots: Vec<u32>,
    /// The keys in id order.
    pub(super) keys: Vec<Key>,
    pub(super) mask: usize,
    /// Selects the id bits of a slot; the rest hold hash bits. Ids stay below it, so a slot is never `EMPTY`.
    pub(super) id_mask: u32,
}

pub(super) const EMPTY: u32 = u32::MAX;

impl KeyTable {
    /// A table with room for `n` keys that will never hold more than `max_keys`.
    ///
    /// # Panics
    /// If `max_keys` ≥ 2³¹.
    pub(super) fn with_capacity(n: usize, max_keys: usize) -> Self {
        assert!(max_keys < 1 << 31, "too many lattice vertices for 32-bit ids");
        let id_bits = usize::BITS - max_keys.leading_zeros();
        let cap = (n + n / 3 + 1).next_power_of_two().max(16);
        KeyTable { slots: vec![EMPTY; cap], keys: Vec::with_capacity(n), mask: cap - 1, id_mask: (1 << id_bits) - 1 }
    }

    /// Number of keys.
    pub(super) fn len(&self) -> usize {
        self.keys.len()
    }

    /// The slot of key id `id` with hash `h`.
    #[inline]
    pub(super) fn slot(&self, h: u64, id: usize) -> u32 {
        (h >> 32) as u32 & !self.id_mask | id as u32
    }

    /// Rehashes into a table twice the size (ids are kept, so vertex numbering does not change).
    pub(super) fn grow(&mut self) {
        let cap = self.slots.len() * 2;
        self.slots = vec![EMPTY; cap];
        self.mask = cap - 1;
        for (id, key) in self.keys.iter().enumerate() {
            let h = Self::hash(key);
            let mut s = h as usize & self.mask;
            while self.slots[s] != EMPTY {
                s = (s + 1) & self.mask;
            }
            self.slots[s] = self.slot(h, id);
        }
    }

    #[inline]
    pub(super) fn hash(key: &Key) -> u64 {
        let Key { lo, hi } = *key;
        let h = (lo ^ u64::from(hi).rotate_right(23)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let h = (h ^ (h >> 32)).wrapping_mul(0xD6E8_FEB8_6659_FD93);
        h ^ (h >> 32)
    }

    /// Whether `slot` holds `key` (whose hash is `h`); the key itself is read only when the hash bits match.
    #[inline]
    pub(super) fn holds(&self, slot: u32, h: u64, key: &Key) -> bool {
        slot != EMPTY
            && (slot ^ (h >> 32) as u32) & !self.id_mask == 0
            && self.keys[(slot & self.id_mask) as usize] == *key
    }

    /// Linear probing from hash `h`: the slot index holding `key`, or the empty slot where it would go.
    #[inline]
    pub(super) fn probe(&self, h: u64, key: &Key) -> usize {
        let mut s = h as usize & self.mask;
        while self.slots[s] != EMPTY && !self.holds(self.slots[s], h, key) {
            s = (s + 1) & self.mask;
        }
        s
    }

    /// The id of `key`, inserting it with the next id (the number of keys so far) if absent. Doubles the
    /// table when it would become more than 3/4 full, so probing always ends (images with very noisy colours
    /// have up to d+1 distinct vertices per pixel).
    pub(super) fn insert(&mut self, key: &Key) -> u32 {
        if 4 * (self.keys.len() + 1) > 3 * self.slots.len() {
            self.grow();
        }
        let h = Self::hash(key);
        let s = self.probe(h, key);
        if self.slots[s] == EMPTY {
            let id = self.keys.len();
            self.slots[s] = self.slot(h, id);
            self.keys.push(*key);
        }
        self.slots[s] & self.id_mask
    }

    /// [`KeyTable::get`] for many keys: the first slot of every key is loaded in a branch-free loop before any
    /// is examined, so the cache misses overlap instead of waiting on each other.
    pub(super) fn get_many(&self, keys: &[Key], ids: &mut [u32]) {
        const MAX: usize = 128;
        for (keys, ids) in keys.chunks(MAX).zip(ids.chunks_mut(MAX)) {
            let mut hashes = [0u64; MAX];
            let mut first = [0u32; MAX];
            for ((h, f), key) in hashes.iter_mut().zip(first.iter_mut()).zip(keys) {
                *h = Self::hash(key);
                *f = self.slots[*h as usize & self.mask];
            }
            for (((id, key), &h), &f) in ids.iter_mut().zip(keys).zip(&hashes).zip(&first) {
                *id = match f {
                    EMPTY => NONE,
                    _ if self.holds(f, h, key) => f & self.id_mask,
                    _ => self.get(key),
                };
            }
        }
    }

    /// The id of `key`, or `NONE`.
    pub(super) fn get(&self, key: &Key) -> u32 {
        let slot = self.slots[self.probe(Self::hash(key), key)];
        if slot == EMPTY { NONE } else { slot & self.id_mask }
    }
}
