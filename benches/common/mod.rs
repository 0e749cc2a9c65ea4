//! Helpers shared by the benchmarks that write a report to `reports/bench/`: the output
//! collector, a deterministic generator and the report header (date, machine, commit).
#![allow(dead_code)]

/// Collects the output to print and to write to the report.
#[derive(Default)]
pub struct Out {
    pub text: String,
}

impl Out {
    /// Prints `s` and keeps it for the report.
    pub fn line(&mut self, s: impl AsRef<str>) {
        println!("{}", s.as_ref());
        self.text.push_str(s.as_ref());
        self.text.push('\n');
    }
}

/// SplitMix64: a small deterministic generator.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `0..n`.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The report's first line: `# DATE KERNEL; N CPUs (MODEL); git COMMIT[+dirty]`.
pub fn header() -> String {
    let cmd = |c: &str, a: &[&str]| {
        std::process::Command::new(c)
            .args(a)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_else(|| "?".into())
    };
    let dirty =
        if cmd("git", &["status", "--porcelain", "--untracked-files=no"]).is_empty() { "" } else { "+dirty" };
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "?".into());
    format!(
        "# {} {}; {} CPUs ({cpu}); git {}{dirty}",
        cmd("date", &["-u", "+%Y-%m-%dT%H:%M:%SZ"]),
        cmd("uname", &["-srm"]),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        cmd("git", &["rev-parse", "--short", "HEAD"])
    )
}
