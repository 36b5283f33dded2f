//! A small `--flag [value]` parser: the CLI needs nothing more, so no dependency for it.

use std::collections::BTreeMap;

/// Parsed options: `--name value` pairs and bare `--switch`es.
#[derive(Debug, Default)]
pub struct Args {
    values: BTreeMap<String, String>,
    switches: Vec<String>,
}

/// Options that take no value.
const SWITCHES: &[&str] = &["json", "implicit", "system", "quiet"];

impl Args {
    pub fn parse(argv: &[String]) -> Result<Self, String> {
        let mut args = Args::default();
        let mut it = argv.iter();
        while let Some(a) = it.next() {
            let Some(name) = a.strip_prefix("--") else {
                return Err(format!("unexpected argument '{a}'"));
            };
            if SWITCHES.contains(&name) {
                args.switches.push(name.to_owned());
            } else {
                let v = it.next().ok_or_else(|| format!("--{name} needs a value"))?;
                args.values.insert(name.to_owned(), v.clone());
            }
        }
        Ok(args)
    }

    /// The value of `--name`, if given.
    pub fn value(&self, name: &str) -> Option<&str> {
        self.values.get(name).map(String::as_str)
    }

    /// The value of `--name`, or an error naming it.
    pub fn required(&self, name: &str) -> Result<&str, String> {
        self.value(name)
            .ok_or_else(|| format!("--{name} is required"))
    }

    /// The value of `--name` parsed, or `default` when absent.
    pub fn parsed_or<T: std::str::FromStr>(&self, name: &str, default: T) -> Result<T, String> {
        match self.value(name) {
            None => Ok(default),
            Some(v) => v
                .parse()
                .map_err(|_| format!("--{name}: cannot parse '{v}'")),
        }
    }

    /// Whether `--name` was given.
    pub fn switch(&self, name: &str) -> bool {
        self.switches.iter().any(|s| s == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Args, String> {
        Args::parse(&s.split_whitespace().map(String::from).collect::<Vec<_>>())
    }

    #[test]
    fn values_switches_and_errors() {
        let a = parse("--headset quest3 --json --texel 16").unwrap();
        assert_eq!(a.value("headset"), Some("quest3"));
        assert!(a.switch("json"));
        assert_eq!(a.parsed_or("texel", 32u32).unwrap(), 16);
        assert_eq!(a.parsed_or("missing", 32u32).unwrap(), 32);
        assert!(parse("--headset").is_err());
        assert!(parse("stray").is_err());
        assert!(a.required("out").unwrap_err().contains("--out"));
    }
}
