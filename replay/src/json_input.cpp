#include "json_input.h"

#include "scanclean/core/errors.h"

namespace scanclean::detail {

nlohmann::json parse_json_input(const std::string& text, const std::string& file) {
  using nlohmann::json;
  std::string last_key;  // the key whose value is being parsed (for messages)
  const json::parser_callback_t track = [&last_key](int, json::parse_event_t event, json& parsed) {
    if (event == json::parse_event_t::key && parsed.is_string())
      last_key = parsed.get<std::string>();
    return true;
  };
  try {
    return json::parse(text, track);
  } catch (const json::parse_error& e) {
    throw InputError(file, byte_place(e.byte), std::string("not valid JSON: ") + e.what());
  } catch (const json::out_of_range& e) {
    throw InputError(file, last_key.empty() ? std::string() : "key \"" + last_key + "\"",
                     std::string("a number out of range (expected a finite double): ") + e.what());
  } catch (const json::exception& e) {
    throw InputError(file, last_key.empty() ? std::string() : "key \"" + last_key + "\"",
                     std::string("not valid JSON: ") + e.what());
  }
}

}  // namespace scanclean::detail
