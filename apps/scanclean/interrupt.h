#pragma once
//! The program's one Ctrl-C (SIGINT) handler. Long commands (capture, replay, record) install it
//! before their loop and poll interrupted(); they stop cleanly, keep what they have, and exit 130.

namespace scanclean::app {

//! Installs the SIGINT handler and clears the flag.
void install_sigint_handler();
//! True once SIGINT arrived after install_sigint_handler().
bool interrupted();

}  // namespace scanclean::app
