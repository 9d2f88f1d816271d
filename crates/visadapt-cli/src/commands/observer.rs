//! `visadapt observer`: the model's quantities for one adaptation luminance.

use crate::cli::ObserverArgs;
use crate::report;
use visadapt::observer::Observer;

pub fn run(args: ObserverArgs) -> anyhow::Result<()> {
    let o = Observer::new(
        args.adaptation,
        args.scotopic,
        Some(args.display.display_max),
    )?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&visadapt::report::observer_json(&o))?
        );
    } else {
        print!("{}", report::observer_text(&o));
    }
    Ok(())
}
