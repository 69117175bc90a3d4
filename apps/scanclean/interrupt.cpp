#include "scanclean/interrupt.h"

#include <csignal>

namespace scanclean::app {

namespace {
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_sigint(int) {
  g_interrupted = 1;
}
}  // namespace

void install_sigint_handler() {
  g_interrupted = 0;
  std::signal(SIGINT, on_sigint);
}

bool interrupted() {
  return g_interrupted != 0;
}

}  // namespace scanclean::app
