//! Tracks: the keypoints of different images that show the same scene point, built by
//! union-find over verified matches (as COLMAP's correspondence graph). A track that would
//! hold two keypoints of one image is inconsistent (a wrong match joined two points); it is
//! cut to its first keypoint per image in (image, keypoint) order.

/// A keypoint of an image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Node {
    pub image: u32,
    pub keypoint: u32,
}

/// Verified matches of one image pair: keypoint indices in image `a` and image `b`.
#[derive(Clone, Debug)]
pub struct PairMatches {
    pub a: u32,
    pub b: u32,
    pub matches: Vec<(u32, u32)>,
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Tracks of at least two images from the verified matches; `keypoints[i]` is image i's
/// keypoint count. Each track is sorted by image; tracks sorted by their first node.
pub fn build(keypoints: &[usize], pairs: &[PairMatches]) -> Vec<Vec<Node>> {
    let mut offset = vec![0usize; keypoints.len() + 1];
    for (i, &k) in keypoints.iter().enumerate() {
        offset[i + 1] = offset[i] + k;
    }
    let mut parent: Vec<usize> = (0..offset[keypoints.len()]).collect();
    for p in pairs {
        for &(ka, kb) in &p.matches {
            let (x, y) = (offset[p.a as usize] + ka as usize, offset[p.b as usize] + kb as usize);
            let (rx, ry) = (find(&mut parent, x), find(&mut parent, y));
            if rx != ry {
                parent[rx.max(ry)] = rx.min(ry);
            }
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<Node>> = std::collections::BTreeMap::new();
    for image in 0..keypoints.len() {
        for k in 0..keypoints[image] {
            let root = find(&mut parent, offset[image] + k);
            groups.entry(root).or_default().push(Node { image: image as u32, keypoint: k as u32 });
        }
    }
    let mut tracks: Vec<Vec<Node>> = groups
        .into_values()
        .filter_map(|mut t| {
            t.sort();
            t.dedup_by(|b, a| a.image == b.image);
            (t.len() >= 2).then_some(t)
        })
        .collect();
    tracks.sort();
    tracks
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Matches 0↔1 and 1↔2 chain into one track of three; a conflicting match (two keypoints
    /// of image 2 joined through image 0) is cut to one keypoint per image.
    #[test]
    fn chains_and_cuts_conflicts() {
        let pairs = vec![
            PairMatches { a: 0, b: 1, matches: vec![(0, 5), (1, 6)] },
            PairMatches { a: 1, b: 2, matches: vec![(5, 2)] },
            PairMatches { a: 0, b: 2, matches: vec![(1, 3), (1, 4)] },
        ];
        let t = build(&[2, 7, 5], &pairs);
        let n = |image, keypoint| Node { image, keypoint };
        assert_eq!(t, vec![vec![n(0, 0), n(1, 5), n(2, 2)], vec![n(0, 1), n(1, 6), n(2, 3)]]);
    }
}
