//! `--partition i/n`: which share of the work one of n stateless workers (e.g. a Slurm or
//! Kubernetes array job) takes. Every worker computes the same split from the same
//! inputs, so the shares are disjoint and cover everything without coordination.

use std::str::FromStr;

/// Worker `index` of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Partition {
    pub index: u32,
    pub count: u32,
}

impl Partition {
    /// Whether the `i`-th item of an ordered input list is ours.
    pub fn contains_index(&self, i: u64) -> bool {
        i % u64::from(self.count) == u64::from(self.index)
    }

    /// Whether the item named `key` (e.g. an episode id) is ours: FNV-1a of the key, so
    /// the split does not depend on the order the items are listed in.
    pub fn contains_key(&self, key: &str) -> bool {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in key.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        self.contains_index(h)
    }
}

impl std::fmt::Display for Partition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Partition {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let (i, n) = s.split_once('/').ok_or_else(|| format!("{s:?} is not i/n"))?;
        let index: u32 = i.trim().parse().map_err(|_| format!("{i:?} is not a number"))?;
        let count: u32 = n.trim().parse().map_err(|_| format!("{n:?} is not a number"))?;
        if count == 0 || index >= count {
            return Err(format!("partition {index}/{count}: need 0 <= i < n"));
        }
        Ok(Partition { index, count })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn partitions_parse() {
        assert_eq!(
            "1/4".parse::<Partition>().unwrap(),
            Partition { index: 1, count: 4 }
        );
        assert!("4/4".parse::<Partition>().is_err());
        assert!("1".parse::<Partition>().is_err());
        assert!("0/0".parse::<Partition>().is_err());
    }

    #[test]
    fn key_shares_are_disjoint_and_cover_everything() {
        let parts: Vec<Partition> = (0..3).map(|i| Partition { index: i, count: 3 }).collect();
        let mut sizes = [0; 3];
        for k in 0..300 {
            let key = format!("episode-{k}");
            let owners: Vec<usize> = (0..3).filter(|&i| parts[i].contains_key(&key)).collect();
            assert_eq!(owners.len(), 1, "{key}");
            sizes[owners[0]] += 1;
        }
        assert!(sizes.iter().all(|&n| n > 60), "{sizes:?}");
    }
}
