//! serde for `[T; N]` with any `N` (serde's own impls stop at 32), as a sequence of exactly
//! `N` elements, without allocation.

use core::fmt;
use core::marker::PhantomData;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};

/// Serializes an array as a sequence.
pub fn serialize<S, T, const N: usize>(arr: &[T; N], ser: S) -> Result<S::Ok, S::Error>
where
    S: Serializer,
    T: serde::Serialize,
{
    let mut t = ser.serialize_tuple(N)?;
    for x in arr {
        t.serialize_element(x)?;
    }
    t.end()
}

/// Deserializes a sequence of exactly `N` elements into an array.
pub fn deserialize<'de, D, T, const N: usize>(de: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: serde::Deserialize<'de> + Default + Copy,
{
    struct ArrayVisitor<T, const N: usize>(PhantomData<T>);

    impl<'de, T, const N: usize> Visitor<'de> for ArrayVisitor<T, N>
    where
        T: serde::Deserialize<'de> + Default + Copy,
    {
        type Value = [T; N];

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "a sequence of {N} elements")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[T; N], A::Error> {
            let mut out = [T::default(); N];
            for (i, slot) in out.iter_mut().enumerate() {
                *slot = seq
                    .next_element()?
                    .ok_or_else(|| de::Error::invalid_length(i, &self))?;
            }
            if seq.next_element::<de::IgnoredAny>()?.is_some() {
                return Err(de::Error::invalid_length(N + 1, &self));
            }
            Ok(out)
        }
    }

    de.deserialize_tuple(N, ArrayVisitor::<T, N>(PhantomData))
}
