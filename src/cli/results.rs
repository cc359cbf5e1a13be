//! Standard output for subcommands' results: it remembers when its reader
//! has gone, so the command can end quietly (see the `cli` module doc).

use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once a result could not be written because standard output's reader
/// has gone.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Standard output for a subcommand's results (see the `cli` module doc).
pub(crate) struct Results<W: Write>(W);

impl Results<io::BufWriter<io::StdoutLock<'static>>> {
    /// Buffered, for one document written at once (flush before returning).
    pub(crate) fn buffered() -> Self {
        Results(io::BufWriter::new(io::stdout().lock()))
    }
}

impl Results<io::Stdout> {
    /// Line by line, for results that come over time (a stream's frames).
    pub(crate) fn lines() -> Self {
        Results(io::stdout())
    }
}

impl<W: Write> Write for Results<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        noting_closed(self.0.write(buf))
    }

    fn flush(&mut self) -> io::Result<()> {
        noting_closed(self.0.flush())
    }
}

fn noting_closed<T>(result: io::Result<T>) -> io::Result<T> {
    if let Err(e) = &result
        && e.kind() == io::ErrorKind::BrokenPipe
    {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
    }
    result
}

/// Whether a result could not be written because standard output's reader
/// has gone: what failed after that was only its consequence.
pub(crate) fn stdout_closed() -> bool {
    STDOUT_CLOSED.load(Ordering::Relaxed)
}
