//! `rectify.yml`: the rectification in OpenCV's `FileStorage` YAML, as `cv2.FileStorage` writes the results of
//! `cv2.stereoRectify`: R1, R2 (3 × 3), P1, P2 (3 × 4), Q (4 × 4), the image size and each view's rectangle of
//! valid pixels (`validPixROI1`, `validPixROI2`: `[ x, y, width, height ]`, the sequence `FileStorage` writes for a
//! `cv::Rect`), for `cv2.reprojectImageTo3D` and code of one's own (`fs.getNode("Q").mat()`).

use super::Rectification;

/// One `!!opencv-matrix` node of doubles, each value written so that it reads back exactly.
fn matrix(name: &str, rows: &[&[f64]]) -> String {
    let cols = rows.first().map_or(0, |r| r.len());
    let data: Vec<String> = rows.iter().flat_map(|r| r.iter().map(|v| format!("{v:?}"))).collect();
    format!(
        "{name}: !!opencv-matrix\n   rows: {}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
        rows.len(),
        data.join(", ")
    )
}

impl Rectification {
    /// The rectification as `rectify.yml` (see the module doc): what `jem rectify` writes beside the views.
    pub fn rectify_yml(&self) -> String {
        let (t, q) = (self.transforms(), self.q());
        let (w, h) = self.size();
        let mut out = format!("%YAML:1.0\n---\nimage_width: {w}\nimage_height: {h}\n");
        out.push_str(&matrix("R1", &t.r1.each_ref().map(|r| &r[..])));
        out.push_str(&matrix("R2", &t.r2.each_ref().map(|r| &r[..])));
        out.push_str(&matrix("P1", &t.p1.each_ref().map(|r| &r[..])));
        out.push_str(&matrix("P2", &t.p2.each_ref().map(|r| &r[..])));
        out.push_str(&matrix("Q", &q.each_ref().map(|r| &r[..])));
        for (name, (x, y, w, h)) in ["validPixROI1", "validPixROI2"].into_iter().zip(self.valid_rois()) {
            out.push_str(&format!("{name}: [ {x}, {y}, {w}, {h} ]\n"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::formats::parse_yaml;

    /// The file reads back as the rectification's own matrices, exactly, with their shapes and the size.
    #[test]
    fn rectify_yml_holds_the_rectification_exactly() {
        let rect = super::super::tests::rig().rectification((640, 480)).unwrap();
        let nodes = parse_yaml(&rect.rectify_yml()).unwrap();
        let t = rect.transforms();
        let flat = |m: &[&[f64]]| m.iter().flat_map(|r| r.iter().copied()).collect::<Vec<f64>>();
        let q = rect.q();
        for (name, rows, cols, data) in [
            ("R1", 3, 3, flat(&t.r1.each_ref().map(|r| &r[..]))),
            ("R2", 3, 3, flat(&t.r2.each_ref().map(|r| &r[..]))),
            ("P1", 3, 4, flat(&t.p1.each_ref().map(|r| &r[..]))),
            ("P2", 3, 4, flat(&t.p2.each_ref().map(|r| &r[..]))),
            ("Q", 4, 4, flat(&q.each_ref().map(|r| &r[..]))),
        ] {
            let node = &nodes[name];
            assert_eq!((node.rows, node.cols, &node.data), (rows, cols, &data), "{name}");
        }
        assert_eq!((nodes["image_width"].data[0], nodes["image_height"].data[0]), (640.0, 480.0));
        for (name, roi) in ["validPixROI1", "validPixROI2"].into_iter().zip(rect.valid_rois()) {
            assert_eq!(nodes[name].data, [roi.0, roi.1, roi.2, roi.3].map(|v| v as f64), "{name}");
        }
        // Q takes a pixel and its disparity to the point the rectified left camera sees there.
        let (x, y, d) = (100.0, 50.0, 20.0);
        let p: Vec<f64> = q.iter().map(|r| r[0] * x + r[1] * y + r[2] * d + r[3]).collect();
        assert!((p[2] / p[3] - rect.focal_px() * rect.baseline() / d).abs() < 1e-9 * rect.baseline().abs().max(1.0));
    }
}
