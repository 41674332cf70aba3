// Enum <-> name tables: each enum the tools spell (log headers, command lines, metrics.json)
// has ONE table, `EnumNames<E>::kNames`, specialised next to the enum; `enum_name` writes from
// it and `parse_enum` reads with it. A table lists every enumerator once under its canonical
// name and may add aliases (old spellings) that parse_enum accepts and nothing writes.
// Thread safety: constexpr data and pure functions. Costs: O(table size) per lookup, no
// allocation except the strings `enum_names`, `enum_name_list` and parse_enum's error return.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace fastslam::engine {

template <class E>
struct EnumName {
  E value;
  std::string_view name;
  bool alias = false;  // accepted by parse_enum, never written
};

// Specialised for each named enum E with
//   static constexpr std::string_view kWhat;              what a value names ("motion kind")
//   static constexpr std::array<EnumName<E>, N> kNames;  canonical names, then any aliases
template <class E>
struct EnumNames;

// The canonical name of `value`; "unknown" for a value outside the table.
template <class E>
constexpr std::string_view enum_name(E value) noexcept {
  for (const EnumName<E>& n : EnumNames<E>::kNames) {
    if (!n.alias && n.value == value) return n.name;
  }
  return "unknown";
}

// Whether `value` is one of the table's enumerators.
template <class E>
constexpr bool enum_known(E value) noexcept {
  for (const EnumName<E>& n : EnumNames<E>::kNames) {
    if (n.value == value) return true;
  }
  return false;
}

// The canonical names in table order (CLI11's IsMember takes them).
template <class E>
std::vector<std::string> enum_names() {
  std::vector<std::string> out;
  for (const EnumName<E>& n : EnumNames<E>::kNames) {
    if (!n.alias) out.emplace_back(n.name);
  }
  return out;
}

// The canonical names for a message: "a, b or c".
template <class E>
std::string enum_name_list() {
  const std::vector<std::string> names = enum_names<E>();
  std::string out;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) out += i + 1 == names.size() ? " or " : ", ";
    out += names[i];
  }
  return out;
}

// The enumerator `text` names, canonically or by an alias. Throws std::invalid_argument
// "unknown <what> '<text>' (<the canonical names>)" for any other text.
template <class E>
E parse_enum(std::string_view text) {
  for (const EnumName<E>& n : EnumNames<E>::kNames) {
    if (n.name == text) return n.value;
  }
  throw std::invalid_argument("unknown " + std::string(EnumNames<E>::kWhat) + " '" +
                              std::string(text) + "' (" + enum_name_list<E>() + ")");
}

}  // namespace fastslam::engine
