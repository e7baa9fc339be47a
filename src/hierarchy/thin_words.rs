//! A boxed `[u32]` behind a thin pointer: the storage of a [`super::LinkCoupling`]'s words.
//!
//! A `Box<[u32]>` is a pointer and a length, 16 bytes; links are what a large solve is made of (office3
//! holds 518k, the 1M-polygon hall 8.6M), and the 8 bytes of the length made a `Link` 32 bytes instead
//! of 24. Here the length lives in the allocation's first word, where the allocator's rounding of the
//! block it hands out usually has room for it (a linear link's 176 bytes and 180 bytes both take a
//! 192-byte block), and an empty list holds no allocation at all (a blocked link's coupling).

use std::ptr::NonNull;

/// An owned list of `u32` words, 8 bytes on its owner's side: `None` for an empty list, otherwise a
/// pointer to `[len, words...]` allocated as a `Box<[u32]>` of `len + 1` words.
#[derive(Default)]
pub struct ThinWords(Option<NonNull<u32>>);

// SAFETY: a `ThinWords` owns its allocation exclusively, as a `Box<[u32]>` does, and `u32` is `Send`
// and `Sync`; shared references only read it.
unsafe impl Send for ThinWords {}
unsafe impl Sync for ThinWords {}

impl ThinWords {
    /// A copy of `words` (no allocation when empty).
    pub fn new(words: &[u32]) -> Self {
        let mut thin = Self::zeroed(words.len());
        thin.copy_from_slice(words);
        thin
    }

    /// `len` zero words (no allocation when `len` is 0), to fill in place.
    pub fn zeroed(len: usize) -> Self {
        if len == 0 {
            return ThinWords(None);
        }
        let count = u32::try_from(len).expect("a coupling holds fewer than 2³² words");
        let mut boxed = vec![0u32; len + 1].into_boxed_slice();
        boxed[0] = count;
        let raw = Box::into_raw(boxed).cast::<u32>();
        ThinWords(Some(
            NonNull::new(raw).expect("a Box never holds a null pointer"),
        ))
    }

    /// The first word (the length) and the number of words after it.
    fn parts(&self) -> Option<(NonNull<u32>, usize)> {
        self.0.map(|first| {
            // SAFETY: `first` points to the length word of a live allocation of `len + 1` words.
            (first, unsafe { first.as_ptr().read() } as usize)
        })
    }
}

impl std::ops::Deref for ThinWords {
    type Target = [u32];

    fn deref(&self) -> &[u32] {
        match self.parts() {
            // SAFETY: the `len` words after the first are initialised, live for as long as `self`,
            // and only written through `&mut self`.
            Some((first, len)) => unsafe { std::slice::from_raw_parts(first.as_ptr().add(1), len) },
            None => &[],
        }
    }
}

impl std::ops::DerefMut for ThinWords {
    fn deref_mut(&mut self) -> &mut [u32] {
        match self.parts() {
            // SAFETY: as in `deref`, and `&mut self` makes this the only reference.
            Some((first, len)) => unsafe {
                std::slice::from_raw_parts_mut(first.as_ptr().add(1), len)
            },
            None => &mut [],
        }
    }
}

impl Drop for ThinWords {
    fn drop(&mut self) {
        if let Some((first, len)) = self.parts() {
            let all = std::ptr::slice_from_raw_parts_mut(first.as_ptr(), len + 1);
            // SAFETY: `all` is exactly the `Box<[u32]>` that `new` leaked, freed once, here.
            drop(unsafe { Box::from_raw(all) });
        }
    }
}

impl Clone for ThinWords {
    fn clone(&self) -> Self {
        ThinWords::new(self)
    }
}

impl PartialEq for ThinWords {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl std::fmt::Debug for ThinWords {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_read_back_clone_and_change_independently() {
        for len in [0usize, 1, 2, 3, 44, 1000] {
            let words: Vec<u32> = (0..len as u32)
                .map(|i| i.wrapping_mul(2_654_435_761))
                .collect();
            let thin = ThinWords::new(&words);
            assert_eq!(&*thin, words.as_slice());
            let mut copy = thin.clone();
            assert_eq!(copy, thin);
            if let Some(first) = copy.first_mut() {
                *first ^= 1;
                assert_ne!(copy, thin);
                assert_eq!(&*thin, words.as_slice(), "the original is left alone");
            }
            drop(thin);
            assert_eq!(copy.len(), len);
        }
        assert_eq!(std::mem::size_of::<ThinWords>(), 8);
        assert!(ThinWords::default().is_empty());
    }
}
