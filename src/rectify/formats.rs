//! Calibration files: OpenCV's `FileStorage` (YAML and XML, as `cv2.FileStorage` writes a stereo calibration) and
//! KITTI's `calib_cam_to_cam.txt`, read into named numeric nodes. Only what a stereo calibration uses is
//! understood: top-level scalars, sequences, `opencv-matrix` nodes (rows, cols, dt, data; a multi-channel `dt`
//! such as `3d` makes each row `cols × channels` values) and `opencv-nd-matrix` nodes (sizes, dt, data: what
//! `cv2.FileStorage` writes for a 1-D numpy array, a vector); anything else is skipped. A top-level name given
//! twice is refused: OpenCV reads the first, other readers the last, and the two would rectify differently.

use std::collections::BTreeMap;

/// A top-level node: its numbers, and the shape when it is a matrix.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Node {
    pub(crate) rows: usize,
    pub(crate) cols: usize,
    pub(crate) data: Vec<f64>,
}

/// The nodes of a file, by name.
pub(crate) type Nodes = BTreeMap<String, Node>;

/// Which kind of file the text is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Format {
    OpenCvYaml,
    OpenCvXml,
    Kitti,
}

/// The format of a calibration file, from its content.
pub(crate) fn sniff(text: &str) -> Option<Format> {
    let head = text.trim_start_matches('\u{feff}').trim_start();
    if head.starts_with("%YAML") || text.contains("!!opencv-matrix") {
        Some(Format::OpenCvYaml)
    } else if head.starts_with("<?xml") || head.starts_with("<opencv_storage") {
        Some(Format::OpenCvXml)
    } else if text.lines().any(|l| l.trim_start().starts_with("K_02:") || l.trim_start().starts_with("P_rect_02:")) {
        Some(Format::Kitti)
    } else {
        None
    }
}

/// Numbers separated by whitespace and commas.
fn numbers(text: &str) -> Result<Vec<f64>, String> {
    text.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f64>().map_err(|_| format!("{:?} is not a number", s.chars().take(30).collect::<String>())))
        .collect()
}

/// Records a top-level name, refusing one seen before.
fn first_time(seen: &mut std::collections::BTreeSet<String>, name: &str) -> Result<(), String> {
    if seen.insert(name.to_string()) {
        return Ok(());
    }
    Err(format!("{name} is given twice (OpenCV reads the first, other readers the last); keep one"))
}

/// The channels of an OpenCV `dt` (`d`: 1, `"3d"`: 3).
fn channels(dt: &str) -> usize {
    let digits: String = dt.trim().trim_matches('"').chars().take_while(char::is_ascii_digit).collect();
    digits.parse().unwrap_or(1).max(1)
}

/// The shape of an `opencv-nd-matrix` of these `sizes`: one size is a vector (1 × n), two are rows × cols, more
/// are the first × the product of the rest.
fn nd_shape(sizes: &[f64], name: &str) -> Result<(usize, usize), String> {
    let whole = |v: f64| (v >= 0.0 && v.fract() == 0.0 && v < 1e9).then_some(v as usize);
    let dims: Option<Vec<usize>> = sizes.iter().map(|&v| whole(v)).collect();
    match dims.as_deref() {
        Some([n]) => Ok((1, *n)),
        Some([r, rest @ ..]) if !rest.is_empty() => Ok((*r, rest.iter().product())),
        _ => Err(format!("{name}: an opencv-nd-matrix needs sizes (whole numbers)")),
    }
}

/// A node from its numbers: a vector (1 × n) unless rows and cols are given.
fn node(data: Vec<f64>, shape: Option<(usize, usize)>, name: &str) -> Result<Node, String> {
    let (rows, cols) = shape.unwrap_or((1, data.len()));
    if rows.checked_mul(cols) != Some(data.len()) {
        return Err(format!("{name}: {rows}×{cols} matrix with {} values", data.len()));
    }
    Ok(Node { rows, cols, data })
}

/// OpenCV's YAML: `%YAML:1.0`, `---`, then `name: value` lines, a value being a number, a `[ ... ]` sequence
/// (over several lines) or `!!opencv-matrix` followed by indented `rows`, `cols`, `dt` and `data: [ ... ]`.
pub(crate) fn parse_yaml(text: &str) -> Result<Nodes, String> {
    let mut nodes = Nodes::new();
    let mut seen = std::collections::BTreeSet::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        i += 1;
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') || trimmed.starts_with('%') || trimmed.starts_with("---") {
            continue;
        }
        if line.starts_with([' ', '\t']) {
            continue; // the inside of a node this reader does not use
        }
        let Some((name, value)) = trimmed.split_once(':') else { continue };
        let (name, value) = (name.trim().to_string(), value.trim());
        first_time(&mut seen, &name)?;
        if value.contains("opencv-matrix") || value.contains("opencv-nd-matrix") {
            let (mut rows, mut cols, mut sizes, mut dt, mut data) = (None, None, None, 1, None);
            while i < lines.len() && lines[i].starts_with([' ', '\t']) {
                let field = lines[i].trim();
                i += 1;
                let Some((k, v)) = field.split_once(':') else { continue };
                // A sequence's value may go on over the next lines, up to its ']'.
                let mut sequence = || -> Result<Vec<f64>, String> {
                    let mut seq = v.trim().to_string();
                    while !seq.contains(']') && i < lines.len() {
                        seq.push(' ');
                        seq.push_str(lines[i].trim());
                        i += 1;
                    }
                    let inner = seq.trim().trim_start_matches('[');
                    numbers(inner.split(']').next().unwrap_or("")).map_err(|e| format!("{name}: {e}"))
                };
                match k.trim() {
                    "rows" => rows = v.trim().parse::<usize>().ok(),
                    "cols" => cols = v.trim().parse::<usize>().ok(),
                    "dt" => dt = channels(v),
                    "sizes" => sizes = Some(sequence()?),
                    "data" => data = Some(sequence()?),
                    _ => {}
                }
            }
            let shape = match (rows, cols, sizes) {
                (Some(r), Some(c), _) => (r, c * dt),
                (_, _, Some(sizes)) => nd_shape(&sizes, &name).map(|(r, c)| (r, c * dt))?,
                _ => return Err(format!("{name}: an opencv-matrix needs rows, cols and data")),
            };
            let Some(data) = data else { return Err(format!("{name}: an opencv-matrix needs rows, cols and data")) };
            nodes.insert(name.clone(), node(data, Some(shape), &name)?);
        } else if value.starts_with('[') {
            let mut seq = value.to_string();
            while !seq.contains(']') && i < lines.len() {
                seq.push(' ');
                seq.push_str(lines[i].trim());
                i += 1;
            }
            let inner = seq.trim_start_matches('[').split(']').next().unwrap_or("");
            if let Ok(data) = numbers(inner) {
                nodes.insert(name.clone(), node(data, None, &name)?);
            }
        } else if let Ok(v) = value.trim_matches('"').parse::<f64>() {
            nodes.insert(name, Node { rows: 1, cols: 1, data: vec![v] });
        }
    }
    Ok(nodes)
}

/// OpenCV's XML: `<opencv_storage>` holding one element per node: `<K1 type_id="opencv-matrix"><rows>3</rows>
/// <cols>3</cols><dt>d</dt><data>…</data></K1>`, or numbers as the element's text.
pub(crate) fn parse_xml(text: &str) -> Result<Nodes, String> {
    let start = text.find("<opencv_storage>").ok_or("no <opencv_storage> element")?;
    let end = text.rfind("</opencv_storage>").ok_or("no </opencv_storage> end tag")?;
    let mut body = &text[start + "<opencv_storage>".len()..end.max(start + "<opencv_storage>".len())];
    let mut nodes = Nodes::new();
    let mut seen = std::collections::BTreeSet::new();
    loop {
        body = body.trim_start();
        if body.starts_with("<!--") {
            let close = body.find("-->").ok_or("an unterminated <!-- comment")?;
            body = &body[close + 3..];
            continue;
        }
        let Some(rest) = body.strip_prefix('<') else { break };
        let tag_end = rest.find('>').ok_or("an unterminated tag")?;
        let tag = &rest[..tag_end];
        let name = tag.split_whitespace().next().unwrap_or("").trim_end_matches('/').to_string();
        first_time(&mut seen, &name)?;
        if tag.ends_with('/') {
            body = &rest[tag_end + 1..];
            continue;
        }
        let close = format!("</{name}>");
        let content_end = rest[tag_end + 1..].find(&close).ok_or_else(|| format!("<{name}> has no {close}"))?;
        let content = &rest[tag_end + 1..tag_end + 1 + content_end];
        body = &rest[tag_end + 1 + content_end + close.len()..];
        let field = |f: &str| {
            let open = format!("<{f}>");
            let a = content.find(&open)? + open.len();
            let b = content[a..].find(&format!("</{f}>"))?;
            Some(content[a..a + b].trim())
        };
        if tag.contains("opencv-matrix") || tag.contains("opencv-nd-matrix") {
            let rows = field("rows").and_then(|v| v.parse::<usize>().ok());
            let cols = field("cols").and_then(|v| v.parse::<usize>().ok());
            let dt = field("dt").map_or(1, channels);
            let shape = match (rows, cols, field("sizes")) {
                (Some(r), Some(c), _) => Some((r, c * dt)),
                (_, _, Some(sizes)) => {
                    let sizes = numbers(sizes).map_err(|e| format!("{name}: {e}"))?;
                    Some(nd_shape(&sizes, &name).map(|(r, c)| (r, c * dt))?)
                }
                _ => None,
            };
            let (Some(shape), Some(data)) = (shape, field("data")) else {
                return Err(format!("{name}: an opencv-matrix needs rows, cols and data"));
            };
            let data = numbers(data).map_err(|e| format!("{name}: {e}"))?;
            nodes.insert(name.clone(), node(data, Some(shape), &name)?);
        } else if !content.contains('<')
            && let Ok(data) = numbers(content.trim().trim_matches('"'))
            && !data.is_empty()
        {
            nodes.insert(name.clone(), node(data, None, &name)?);
        }
    }
    Ok(nodes)
}

/// KITTI's `calib_cam_to_cam.txt`: `KEY: numbers` lines (`K_02: fx 0 cx 0 fy cy 0 0 1`, `S_02: w h`, ...); the
/// matrices' shapes are KITTI's (K, R: 3 × 3, P_rect: 3 × 4, the others vectors).
pub(crate) fn parse_kitti(text: &str) -> Result<Nodes, String> {
    let mut nodes = Nodes::new();
    let mut seen = std::collections::BTreeSet::new();
    for line in text.lines() {
        let Some((name, value)) = line.split_once(':') else { continue };
        let name = name.trim();
        first_time(&mut seen, name)?;
        let shape = if name.starts_with("K_") || name.starts_with("R_") {
            Some((3, 3))
        } else if name.starts_with("P_rect_") {
            Some((3, 4))
        } else {
            None
        };
        // Other lines (calib_time: a date) are not numbers: skipped.
        if let Ok(data) = numbers(value) {
            if data.is_empty() {
                continue;
            }
            nodes.insert(name.to_string(), node(data, shape, name)?);
        }
    }
    Ok(nodes)
}

#[cfg(test)]
mod tests {
    use super::*;

    const YAML: &str = "%YAML:1.0\n---\nimage_width: 640\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
                        data: [ 7.0e+02, 0., 3.2e+02, 0., 7.0e+02,\n       2.4e+02, 0., 0., 1. ]\nD1: !!opencv-matrix\n   \
                        rows: 1\n   cols: 5\n   dt: d\n   data: [ -0.1, 0.01, 0., 0., 0. ]\nsize: [ 640, 480 ]\n";

    #[test]
    fn yaml_matrices_scalars_and_sequences_are_read() {
        assert_eq!(sniff(YAML), Some(Format::OpenCvYaml));
        let n = parse_yaml(YAML).unwrap();
        assert_eq!((n["K1"].rows, n["K1"].cols), (3, 3));
        assert_eq!(n["K1"].data[5], 240.0);
        assert_eq!(n["D1"].data, vec![-0.1, 0.01, 0.0, 0.0, 0.0]);
        assert_eq!(n["image_width"].data, vec![640.0]);
        assert_eq!(n["size"].data, vec![640.0, 480.0]);
    }

    #[test]
    fn xml_matrices_and_scalars_are_read() {
        let xml = "<?xml version=\"1.0\"?>\n<opencv_storage>\n<!-- a note -->\n<R type_id=\"opencv-matrix\">\n  \
                   <rows>3</rows>\n  <cols>3</cols>\n  <dt>d</dt>\n  <data>\n    1. 0. 0. 0. 1. 0.\n    0. 0. 1.</data>\
                   </R>\n<image_height>480</image_height>\n</opencv_storage>\n";
        assert_eq!(sniff(xml), Some(Format::OpenCvXml));
        let n = parse_xml(xml).unwrap();
        assert_eq!(n["R"].data, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        assert_eq!(n["image_height"].data, vec![480.0]);
    }

    #[test]
    fn kitti_lines_are_read_with_their_shapes_and_the_date_is_skipped() {
        let text = "calib_time: 09-Jan-2012 13:57:47\nS_02: 1.392000e+03 5.120000e+02\n\
                    K_02: 9.597910e+02 0 6.960217e+02 0 9.569251e+02 2.241806e+02 0 0 1\n\
                    P_rect_02: 7.2e+02 0 6.0e+02 4.4e+01 0 7.2e+02 1.7e+02 2.1e-01 0 0 1 2.7e-03\n";
        assert_eq!(sniff(text), Some(Format::Kitti));
        let n = parse_kitti(text).unwrap();
        assert_eq!((n["K_02"].rows, n["P_rect_02"].cols, n["S_02"].cols), (3, 4, 2));
        assert!(!n.contains_key("calib_time"));
    }

    /// What `cv2.FileStorage` writes for a 1-D numpy array (`np.array([...])`): an `opencv-nd-matrix` with one size,
    /// read as a vector; in XML too. A multi-channel matrix holds `cols × channels` values a row.
    #[test]
    fn nd_matrices_and_multi_channel_matrices_are_read() {
        let yaml = "%YAML 1.2\n---\nD1: !!opencv-nd-matrix\n   sizes: [ 5 ]\n   dt: d\n   data: [ -0.21, 0.09,\n       \
                    0.0012, -0.0007,\n       -0.015 ]\nZ: !!opencv-matrix\n   rows: 1\n   cols: 2\n   dt: \"3d\"\n   \
                    data: [ 1., 2., 3., 4., 5., 6. ]\n";
        let n = parse_yaml(yaml).unwrap();
        assert_eq!((n["D1"].rows, n["D1"].cols), (1, 5));
        assert_eq!(n["D1"].data, vec![-0.21, 0.09, 0.0012, -0.0007, -0.015]);
        assert_eq!((n["Z"].rows, n["Z"].cols), (1, 6));
        let xml = "<?xml version=\"1.0\"?>\n<opencv_storage>\n<T type_id=\"opencv-nd-matrix\">\n  \
                   <sizes>\n    3</sizes>\n  <dt>d</dt>\n  <data>\n    -0.12 0.0035 -0.0021</data></T>\n\
                   </opencv_storage>\n";
        let n = parse_xml(xml).unwrap();
        assert_eq!((n["T"].rows, n["T"].cols, n["T"].data.len()), (1, 3, 3));
    }

    /// A name given twice is refused, naming it: OpenCV takes the first, jem took the last.
    #[test]
    fn a_name_given_twice_is_refused() {
        let twice = "%YAML:1.0\nT: [ 1, 0, 0 ]\nimage_width: 640\nT: [ -1, 0, 0 ]\n";
        assert!(parse_yaml(twice).unwrap_err().contains("T is given twice"));
        let xml = "<opencv_storage><image_width>640</image_width><image_width>320</image_width></opencv_storage>";
        assert!(parse_xml(xml).unwrap_err().contains("image_width is given twice"));
        assert!(
            parse_kitti("S_02: 1 2\nK_02: 1 0 0 0 1 0 0 0 1\nS_02: 3 4\n").unwrap_err().contains("S_02 is given twice")
        );
    }

    #[test]
    fn a_matrix_whose_data_does_not_fill_it_is_an_error() {
        let bad = "%YAML:1.0\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 2 ]\n";
        assert!(parse_yaml(bad).unwrap_err().contains("K1"));
        assert_eq!(sniff("hello"), None);
    }
}
