//! The `lumen` command line. Exit codes: 0 success; 1 an error (the message names the file,
//! field or value, and starts with whose fault it is: `error (bad-input):`, `(numerical)`,
//! `(io)` or `(unsupported)`); 2 a usage error; 3 a pipeline ran but a metric missed its
//! bound without a declared expected miss, or met a bound declared a miss (the message names
//! the metric).

mod cli;

fn main() {
    // Output piped into `head` and closed early should end the program quietly, as it does a
    // C tool, rather than make `println!` panic.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    std::process::exit(cli::main());
}
