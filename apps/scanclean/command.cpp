#include "scanclean/command.h"

namespace scanclean::app {

std::vector<Command>& command_registry() {
  static std::vector<Command> registry;
  return registry;
}

}  // namespace scanclean::app
