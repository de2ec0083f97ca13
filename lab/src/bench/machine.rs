//! A one-line description of the machine a bench ran on (cores, CPU model, memory, load).

/// `N cores, <model name>, <GiB> GiB RAM, load average <L> (1 min)` from `/proc/cpuinfo`,
/// `/proc/meminfo` and `/proc/loadavg`; parts that cannot be read are shown as `unknown`.
pub fn describe() -> String {
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let model = proc_value(&cpuinfo, "model name").unwrap_or("unknown CPU");
    let memory = proc_value(&meminfo, "MemTotal")
        .and_then(|v| v.trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or("unknown".to_owned(), |kib| {
            format!("{:.1}", kib / 1024.0 / 1024.0)
        });
    format!(
        "{cores} cores, {model}, {memory} GiB RAM, load average {} (1, 5, 15 min)",
        load_average()
    )
}

/// The 1, 5 and 15 minute load averages from `/proc/loadavg`, e.g. `1.63 2.10 3.05`.
pub fn load_average() -> String {
    let text = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let fields: Vec<&str> = text.split_whitespace().take(3).collect();
    if fields.len() == 3 {
        fields.join(" ")
    } else {
        "unknown".to_owned()
    }
}

/// The value of the first `key: value` line with `key` in a `/proc` text.
fn proc_value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
    text.lines().find_map(|line| {
        let (name, value) = line.split_once(':')?;
        (name.trim() == key).then(|| value.trim())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_first_matching_key() {
        let text = "processor\t: 0\nmodel name\t: AMD EPYC\nmodel name\t: other\n";
        assert_eq!(proc_value(text, "model name"), Some("AMD EPYC"));
        assert_eq!(proc_value(text, "flags"), None);
    }
}
