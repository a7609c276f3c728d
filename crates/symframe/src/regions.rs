//! Connected regions of a pixel grid (4-neighbours): the integration's height offsets (one per
//! region of the mask) and the calibration's bright spots both need them.

/// The label of a pixel outside every region.
pub(crate) const OUTSIDE: u32 = u32::MAX;

/// The connected regions (4-neighbours) of the pixels of a `width x height` grid for which
/// `inside(i)` holds: a label per pixel ([`OUTSIDE`] where `inside` does not hold; 32-bit, 4
/// bytes a pixel on images of any size) and each region's pixel count, in label order.
/// `None` where the grid holds more pixels than a 32-bit index reaches.
pub(crate) fn label_regions(
    width: usize,
    height: usize,
    inside: impl Fn(usize) -> bool,
) -> Option<(Vec<u32>, Vec<usize>)> {
    if u32::try_from(width.checked_mul(height)?).is_err() {
        return None;
    }
    let mut label = vec![OUTSIDE; width * height];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..width * height {
        if !inside(start) || label[start] != OUTSIDE {
            continue;
        }
        // Fewer regions than pixels, so below OUTSIDE.
        let id = sizes.len() as u32;
        label[start] = id;
        stack.push(start as u32);
        let mut n = 0usize;
        while let Some(i) = stack.pop() {
            let i = i as usize;
            n += 1;
            let (r, c) = (i / width, i % width);
            let mut push = |j: usize| {
                if inside(j) && label[j] == OUTSIDE {
                    label[j] = id;
                    stack.push(j as u32);
                }
            };
            if c + 1 < width {
                push(i + 1);
            }
            if c > 0 {
                push(i - 1);
            }
            if r + 1 < height {
                push(i + width);
            }
            if r > 0 {
                push(i - width);
            }
        }
        sizes.push(n);
    }
    Some((label, sizes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_touch_by_edges_not_corners() {
        // Two diagonal pixels are two regions; an L of three is one.
        #[rustfmt::skip]
        let grid = [
            1, 0, 0, 1,
            0, 1, 0, 1,
            0, 0, 0, 1,
        ];
        let (label, sizes) = label_regions(4, 3, |i| grid[i] == 1).unwrap();
        assert_eq!(sizes, vec![1, 3, 1]);
        assert_eq!(label[0], 0);
        assert_eq!([label[3], label[7], label[11]], [1, 1, 1]);
        assert_eq!(label[5], 2);
        assert!(label
            .iter()
            .zip(grid)
            .all(|(&l, g)| (l == OUTSIDE) == (g == 0)));
        let (label, sizes) = label_regions(3, 2, |_| false).unwrap();
        assert!(sizes.is_empty() && label.iter().all(|&l| l == OUTSIDE));
    }
}
