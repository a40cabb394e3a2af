// One declaration per parameter (nvblox's shape): name, kind, default, range
// or choices, description, unit and whether it can change while the stage
// runs. A stage's ParamTable binds each declaration to a field of its config
// struct, so that one table
//   - reads the config from any ParamSource (ROS parameters, a YAML section,
//     a dynamic_reconfigure request) and range-checks each value as it is read,
//   - checks a whole config's ranges (the config's validate() calls it),
//   - refuses unknown keys of a YAML section, naming the key and the known ones,
//   - writes the values back (a refused reconfigure reports the kept values),
//   - describes itself to the docs (docs/parameters.md is generated from it)
//     and to the generic test that checks cfg/*.cfg and config/*.yaml.
// The default of each parameter is its config struct's in-class initializer;
// the table reads it from a default-constructed config.
//
// Thread-safety: a table is immutable once built (stages build theirs once, in
// a function-local static), so reads from several threads are safe.
#ifndef FISHEYE_MAPPING_CORE_COMMON_PARAM_TABLE_H_
#define FISHEYE_MAPPING_CORE_COMMON_PARAM_TABLE_H_

#include <functional>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "fisheye_mapping/core/common/params.h"

namespace fisheye_mapping {

enum class ParamKind { Bool, Int, Double, String, Enum, DoubleList, StringList, StringMap };
// "bool" | "int" | "double" | "string" | "enum" | "double list" | "string list" | "string map"
const char* toString(ParamKind kind);

// Whether a parameter may change while the stage runs (dynamic_reconfigure).
enum class ParamChange { StartUp, Runtime };

// The accepted values of a number. Ends are inclusive unless open; `special`
// admits one value outside the range with its own meaning (e.g. 0: no limit),
// stated in the docs, so that no sentinel is reached by clamping.
struct ParamRange {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false;
  bool max_open = false;
  static ParamRange any() { return {}; }
  static ParamRange atLeast(double v) { return {v, std::numeric_limits<double>::infinity(), false, false}; }
  static ParamRange above(double v) { return {v, std::numeric_limits<double>::infinity(), true, false}; }
  static ParamRange between(double lo, double hi) { return {lo, hi, false, false}; }
  // (lo, hi]
  static ParamRange aboveUpTo(double lo, double hi) { return {lo, hi, true, false}; }
  // (lo, hi)
  static ParamRange strictlyBetween(double lo, double hi) { return {lo, hi, true, true}; }
  bool contains(double v) const;
  bool bounded() const { return min > -std::numeric_limits<double>::infinity() || max < std::numeric_limits<double>::infinity(); }
  // "finite", ">= 0", "> 0", "[0, 1]", "(0, 1]", ... (NaN and infinities are never in a range)
  std::string text() const;
};

// A parameter's value, of its kind (Enum as its string).
using ParamValue = std::variant<bool, int, double, std::string, std::vector<double>, std::vector<std::string>,
                                std::map<std::string, std::string>>;
// The value as the docs print it: 0.5, true, "cam0", [60, 60, 3], {} ...
std::string formatParamValue(const ParamValue& v);

// What the docs and the cfg/YAML checks need to know about one parameter.
struct ParamInfo {
  std::string name;
  ParamKind kind = ParamKind::Double;
  std::string description;
  std::string unit;                  // "m", "s", "px", or empty
  ParamChange change = ParamChange::StartUp;
  ParamRange range;                  // Int and Double
  std::vector<std::string> choices;  // Enum
  size_t list_size = 0;              // DoubleList: the number of values (0: any)
  bool optional = false;             // may be unset (no default: something else applies)
  ParamValue default_value;
  // "[0, 1]", "exact | approximate", "3 values", "any" ...
  std::string allowed() const;
  bool runtime() const { return change == ParamChange::Runtime; }
};

// Throws std::invalid_argument "<name>: must be <range>, got <v>" unless v is
// in the range (NaN and infinities never are).
void requireInRange(const std::string& name, const ParamRange& range, double v, const std::string& unit = "");

template <class Config>
class ParamTable {
 public:
  using ConfigType = Config;
  using Get = std::function<ParamValue(const Config&)>;
  // Sets the field from a value of the parameter's kind; throws
  // std::invalid_argument naming the parameter when the value is not accepted.
  using Set = std::function<void(Config&, const ParamValue&)>;
  // Reads the parameter from a source into the config (when present).
  using Read = std::function<bool(const ParamSource&, const std::string&, Config&)>;

  struct Entry {
    ParamInfo info;
    Get get;
    Set set;
    Read read;
  };

  // `section` names the table in messages and docs ("tsdf", "depth").
  explicit ParamTable(std::string section) : section_(std::move(section)) {}

  // ---- declarations (fields reached through an accessor) ----
  template <class Field>
  ParamTable& flag(const std::string& name, Field field, const std::string& description,
                   ParamChange change = ParamChange::StartUp) {
    ParamInfo i = info(name, ParamKind::Bool, description, change);
    return add<bool>(std::move(i), [field](const Config& c) -> ParamValue { return bool(field(const_cast<Config&>(c))); },
               [field](Config& c, const ParamValue& v) { field(c) = std::get<bool>(v); });
  }
  // An int or double field (float and int fields alike), range-checked.
  template <class Field>
  ParamTable& number(const std::string& name, Field field, ParamRange range, const std::string& unit,
                     const std::string& description, ParamChange change = ParamChange::StartUp) {
    using T = std::decay_t<decltype(field(std::declval<Config&>()))>;
    constexpr bool is_int = std::is_integral_v<T>;
    ParamInfo i = info(name, is_int ? ParamKind::Int : ParamKind::Double, description, change);
    i.range = range;
    i.unit = unit;
    return add<std::conditional_t<is_int, int, double>>(
        std::move(i),
        [field](const Config& c) -> ParamValue {
          const T v = field(const_cast<Config&>(c));
          if constexpr (is_int) return int(v); else return double(v);
        },
        [field, name, range, unit](Config& c, const ParamValue& v) {
          const double d = std::holds_alternative<int>(v) ? double(std::get<int>(v)) : std::get<double>(v);
          requireInRange(name, range, d, unit);
          field(c) = static_cast<T>(d);
        });
  }
  template <class Field>
  ParamTable& text(const std::string& name, Field field, const std::string& description,
                   ParamChange change = ParamChange::StartUp) {
    ParamInfo i = info(name, ParamKind::String, description, change);
    return add<std::string>(std::move(i), [field](const Config& c) -> ParamValue { return field(const_cast<Config&>(c)); },
               [field](Config& c, const ParamValue& v) { field(c) = std::get<std::string>(v); });
  }
  // An enumeration: `choices` are its parameter strings, `toText` / `fromText`
  // convert (fromText may assume a valid choice).
  template <class ToText, class FromText>
  ParamTable& choice(const std::string& name, std::vector<std::string> choices, ToText toText, FromText fromText,
                     const std::string& description, ParamChange change = ParamChange::StartUp) {
    ParamInfo i = info(name, ParamKind::Enum, description, change);
    i.choices = choices;
    const std::string allowed = i.allowed();
    return add<std::string>(
        std::move(i), [toText](const Config& c) -> ParamValue { return std::string(toText(c)); },
        [fromText, choices, name, allowed](Config& c, const ParamValue& v) {
          const std::string& s = std::get<std::string>(v);
          bool ok = false;
          for (const auto& ch : choices) ok = ok || ch == s;
          if (!ok) throw std::invalid_argument(name + ": must be one of " + allowed + ", got '" + s + "'");
          fromText(c, s);
        });
  }
  // A list of numbers, each in `range`; `size` values exactly when non-zero.
  template <class GetList, class SetList>
  ParamTable& numbers(const std::string& name, size_t size, ParamRange range, const std::string& unit,
                      GetList getList, SetList setList, const std::string& description) {
    ParamInfo i = info(name, ParamKind::DoubleList, description, ParamChange::StartUp);
    i.list_size = size;
    i.range = range;
    i.unit = unit;
    return add<std::vector<double>>(
        std::move(i), [getList](const Config& c) -> ParamValue { return std::vector<double>(getList(c)); },
        [setList, name, size, range, unit](Config& c, const ParamValue& v) {
          const auto& l = std::get<std::vector<double>>(v);
          if (size && l.size() != size)
            throw std::invalid_argument(name + ": needs " + std::to_string(size) + " values, got " +
                                        std::to_string(l.size()));
          for (double d : l) requireInRange(name, range, d, unit);
          setList(c, l);
        });
  }
  template <class Field>
  ParamTable& names(const std::string& name, Field field, const std::string& description) {
    ParamInfo i = info(name, ParamKind::StringList, description, ParamChange::StartUp);
    return add<std::vector<std::string>>(std::move(i), [field](const Config& c) -> ParamValue { return field(const_cast<Config&>(c)); },
               [field](Config& c, const ParamValue& v) { field(c) = std::get<std::vector<std::string>>(v); });
  }
  template <class Field>
  ParamTable& table(const std::string& name, Field field, const std::string& description) {
    ParamInfo i = info(name, ParamKind::StringMap, description, ParamChange::StartUp);
    return add<std::map<std::string, std::string>>(std::move(i), [field](const Config& c) -> ParamValue { return field(const_cast<Config&>(c)); },
               [field](Config& c, const ParamValue& v) { field(c) = std::get<std::map<std::string, std::string>>(v); });
  }
  // An optional number: unset by default (`unset_meaning` says what applies then).
  template <class Field>
  ParamTable& optionalNumber(const std::string& name, Field field, ParamRange range, const std::string& description,
                             const std::string& unset_meaning, ParamChange change = ParamChange::StartUp) {
    ParamInfo i = info(name, ParamKind::Double, description + " (unset: " + unset_meaning + ")", change);
    i.range = range;
    i.optional = true;
    return add<double>(
        std::move(i),
        [field](const Config& c) -> ParamValue {
          const auto& o = field(const_cast<Config&>(c));
          return o ? double(*o) : std::numeric_limits<double>::quiet_NaN();
        },
        [field, name, range](Config& c, const ParamValue& v) {
          const double d = std::holds_alternative<int>(v) ? double(std::get<int>(v)) : std::get<double>(v);
          requireInRange(name, range, d);
          using T = typename std::decay_t<decltype(field(c))>::value_type;
          field(c) = static_cast<T>(d);
        });
  }
  // Every parameter and rule of `other` (a part of this config reached through `part`).
  template <class Part, class Access>
  ParamTable& include(const ParamTable<Part>& other, Access part) {
    for (const auto& e : other.entries()) {
      auto get = e.get;
      auto set = e.set;
      auto read = e.read;
      entries_.push_back(Entry{e.info, [get, part](const Config& c) { return get(part(const_cast<Config&>(c))); },
                               [set, part](Config& c, const ParamValue& v) { set(part(c), v); },
                               [read, part](const ParamSource& p, const std::string& n, Config& c) {
                                 return read(p, n, part(c));
                               }});
    }
    // ... and its whole-config rules, on the part.
    for (const auto& r : other.rules())
      rules_.push_back([r, part](const Config& c) { r(part(const_cast<Config&>(c))); });
    return *this;
  }
  // Whole-config checks run by check() after the ranges (cross-field rules).
  ParamTable& rule(std::function<void(const Config&)> r) {
    rules_.push_back(std::move(r));
    return *this;
  }

  // ---- use ----
  const std::string& section() const { return section_; }
  const std::vector<Entry>& entries() const { return entries_; }
  const std::vector<std::function<void(const Config&)>>& rules() const { return rules_; }
  std::vector<ParamInfo> infos() const {
    std::vector<ParamInfo> v;
    for (const auto& e : entries_) v.push_back(e.info);
    return v;
  }
  std::set<std::string> names(bool runtime_only = false) const {
    std::set<std::string> s;
    for (const auto& e : entries_)
      if (!runtime_only || e.info.runtime()) s.insert(e.info.name);
    return s;
  }
  const Entry* find(const std::string& name) const {
    for (const auto& e : entries_)
      if (e.info.name == name) return &e;
    return nullptr;
  }

  // `base` overlaid with every declared parameter `p` holds (only the
  // run-time ones when runtime_only), each range-checked as read, then
  // check()ed. Throws std::invalid_argument naming the parameter.
  Config read(const ParamSource& p, Config base, bool runtime_only = false) const {
    for (const auto& e : entries_) {
      if (runtime_only && !e.info.runtime()) continue;
      e.read(p, e.info.name, base);
    }
    check(base);
    return base;
  }
  // Every field in its declared range and every rule holds; throws
  // std::invalid_argument naming the parameter.
  void check(const Config& c) const {
    for (const auto& e : entries_) {
      if (e.info.kind != ParamKind::Int && e.info.kind != ParamKind::Double && e.info.kind != ParamKind::DoubleList)
        continue;
      const ParamValue v = e.get(c);
      if (const double* d = std::get_if<double>(&v)) {
        if (!(e.info.optional && *d != *d)) requireInRange(e.info.name, e.info.range, *d, e.info.unit);
      } else if (const int* i = std::get_if<int>(&v)) {
        requireInRange(e.info.name, e.info.range, *i, e.info.unit);
      } else if (const auto* l = std::get_if<std::vector<double>>(&v)) {
        for (double d : *l) requireInRange(e.info.name, e.info.range, d, e.info.unit);
      }
    }
    for (const auto& r : rules_) r(c);
  }
  // The values of `c`, by name (only the run-time ones when runtime_only).
  std::map<std::string, ParamValue> values(const Config& c, bool runtime_only = false) const {
    std::map<std::string, ParamValue> m;
    for (const auto& e : entries_)
      if (!runtime_only || e.info.runtime()) m[e.info.name] = e.get(c);
    return m;
  }
  // Throws std::invalid_argument naming the first of `keys` that is not
  // declared here (nor in `also`), with the known names.
  void requireKnown(const std::vector<std::string>& keys, const std::string& origin,
                    const std::set<std::string>& also = {}) const {
    std::set<std::string> known = names();
    known.insert(also.begin(), also.end());
    for (const auto& k : keys) {
      if (known.count(k)) continue;
      std::string list;
      for (const auto& n : known) list += (list.empty() ? "" : ", ") + n;
      throw std::invalid_argument(origin + ": unknown parameter '" + k + "' in section '" + section_ +
                                  "' (known: " + list + ")");
    }
  }
  // The defaults (a default-constructed config), for the docs.
  std::vector<ParamInfo> documented() const {
    std::vector<ParamInfo> v;
    const Config defaults{};
    for (const auto& e : entries_) {
      ParamInfo i = e.info;
      i.default_value = e.get(defaults);
      v.push_back(std::move(i));
    }
    return v;
  }

 private:
  ParamInfo info(const std::string& name, ParamKind kind, const std::string& description, ParamChange change) {
    if (find(name)) throw std::logic_error("ParamTable " + section_ + ": '" + name + "' declared twice");
    ParamInfo i;
    i.name = name;
    i.kind = kind;
    i.description = description;
    i.change = change;
    return i;
  }
  // Declares an entry whose value is read from a source as a T.
  template <class T>
  ParamTable& add(ParamInfo i, Get get, Set set) {
    i.default_value = get(Config{});
    Read read = [set](const ParamSource& p, const std::string& name, Config& c) {
      T v{};
      if (!p.get(name, v)) return false;
      set(c, ParamValue(v));
      return true;
    };
    entries_.push_back(Entry{std::move(i), std::move(get), std::move(set), std::move(read)});
    return *this;
  }

  std::string section_;
  std::vector<Entry> entries_;
  std::vector<std::function<void(const Config&)>> rules_;
};

// Keys of a YAML map (empty for anything else).
std::vector<std::string> yamlKeys(const YAML::Node& node);

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_PARAM_TABLE_H_
