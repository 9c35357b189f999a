//! Files a script names for what it writes: kept inside the simulation's output folder and off
//! the files the run writes itself.

/// Checks a file name a script gives for something it writes (`sim.save`, `write_points`,
/// `checkpoint_every`, `plot`): a relative path inside the simulation's output folder, not one of
/// the files the run itself writes there. Outputs stay in the output folder so that the folder
/// holds the whole run (to copy, resume, compare in a batch) and a script cannot overwrite files
/// elsewhere with the user's rights.
/// A file of the output folder a script reads (a checkpoint to resume from, a series): a relative
/// path without `..`.
pub fn check_read_file(call: &str, file: &str) -> std::result::Result<(), String> {
    use std::path::Component;
    let path = std::path::Path::new(file);
    let inside = !file.trim().is_empty()
        && path.components().all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
        && path.file_name().is_some();
    if inside {
        Ok(())
    } else {
        Err(format!(
            "{call}(\"{file}\"): a script reads files of its output folder: give a relative path without `..` \
             (e.g. \"series.csv\" or \"checkpoints/ck.json\")"
        ))
    }
}

pub fn check_script_file(call: &str, file: &str) -> std::result::Result<(), String> {
    use std::path::Component;
    let path = std::path::Path::new(file);
    let inside = !file.trim().is_empty()
        && path.components().all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
        && path.file_name().is_some();
    if !inside {
        return Err(format!(
            "{call}(\"{file}\"): files a script writes go into its output folder: give a relative path without `..` \
             (e.g. \"state.json\" or \"checkpoints/ck.json\"); choose the folder with --out"
        ));
    }
    let name = path.file_name().map(|n| n.to_string_lossy().to_lowercase()).unwrap_or_default();
    // `./series.csv` is `series.csv`.
    let parts: Vec<String> = path
        .components()
        .filter(|c| matches!(c, Component::Normal(_)))
        .map(|c| c.as_os_str().to_string_lossy().to_lowercase())
        .collect();
    let top = parts.len() == 1;
    let first = parts.first().cloned().unwrap_or_default();
    let run_file = top
        && (matches!(
            name.as_str(),
            "series.csv"
                | "summary.json"
                | "provenance.json"
                | "last_good_points.csv"
                | "batch_summary.csv"
                | "stdout.log"
                | "stderr.log"
        ) || (name.starts_with("series_") && name.ends_with(".csv")));
    if run_file || first == "vtk" || name.ends_with(".partial") {
        return Err(format!(
            "{call}(\"{file}\"): the run writes that file itself (series*.csv, summary.json, provenance.json, \
             last_good_points.csv, vtk/): give another name"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::check_script_file;

    #[test]
    fn script_files_stay_in_the_output_folder_and_off_the_run_own_files() {
        for ok in ["ck.json", "./ck.json", "checkpoints/ck.json", "points_end.csv", "rve.json"] {
            assert!(check_script_file("save", ok).is_ok(), "{ok}");
        }
        for outside in ["", "/tmp/ck.json", "../ck.json", "a/../../ck.json", "/etc/passwd", "."] {
            let e = check_script_file("save", outside).unwrap_err();
            assert!(e.contains("relative path without `..`"), "{outside}: {e}");
        }
        for own in [
            "series.csv",
            "./series.csv",
            "series_runout.csv",
            "Summary.json",
            "provenance.json",
            "vtk/points.pvd",
            "./vtk/x.vtu",
        ] {
            let e = check_script_file("checkpoint_every", own).unwrap_err();
            assert!(e.contains("the run writes that file itself"), "{own}: {e}");
        }
    }
}
