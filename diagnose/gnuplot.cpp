#include "diagnose/gnuplot.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <system_error>

extern char** environ;

namespace imubridge::diagnose {
namespace {

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

bool write_file(const std::filesystem::path& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary);
  out << content;
  return static_cast<bool>(out.flush());
}

std::string first_line(const std::string& text) {
  const auto start = text.find_first_not_of(" \t\r\n");
  if (start == std::string::npos) return {};
  return text.substr(start, text.find('\n', start) - start);
}

// A directory only this run uses, removed when it goes out of scope.
class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "imubridge-plots-XXXXXX").string();
    if (::mkdtemp(pattern.data()) != nullptr) path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code ignored;
    if (!path_.empty()) std::filesystem::remove_all(path_, ignored);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// Runs `gnuplot -d script` inside `dir` (so data files are named without paths), its output going to `log`.
// Returns the exit status, or -1 with errno's text in `error` when it could not be started.
int run_gnuplot(const std::filesystem::path& program, const std::filesystem::path& dir, const std::string& script,
                const std::string& log, std::string& error) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addchdir_np(&actions, dir.c_str());
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  // -d: no ~/.gnuplot, so a user's settings cannot change the figures (same input, same bytes).
  std::string program_text = program.string(), defaults = "-d", script_name = script;
  std::array<char*, 4> argv{program_text.data(), defaults.data(), script_name.data(), nullptr};
  pid_t pid = -1;
  const int spawn_error = posix_spawn(&pid, program.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawn_error != 0) {
    error = std::strerror(spawn_error);
    return -1;
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) {
      error = std::strerror(errno);
      return -1;
    }
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

void replace_all(std::string& text, std::string_view from, std::string_view to) {
  for (auto at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
}

}  // namespace

std::optional<std::filesystem::path> find_on_path(std::string_view name) {
  const char* path = std::getenv("PATH");
  if (path == nullptr) return std::nullopt;
  std::string_view dirs = path;
  while (true) {
    const auto colon = dirs.find(':');
    const std::string_view dir = dirs.substr(0, colon);
    const auto candidate = std::filesystem::path(dir.empty() ? "." : std::string(dir)) / std::string(name);
    std::error_code ec;
    if (std::filesystem::is_regular_file(candidate, ec) && ::access(candidate.c_str(), X_OK) == 0) return candidate;
    if (colon == std::string_view::npos) return std::nullopt;
    dirs.remove_prefix(colon + 1);
  }
}

std::string gnuplot_quote(std::string_view text) {
  std::string quoted = "'";
  for (char c : text) {
    if (c == '\'')
      quoted += "''";
    else if (c != '\n' && c != '\r')
      quoted += c;
  }
  return quoted + "'";
}

std::string inline_svg(std::string_view svg_file, std::string_view id_prefix) {
  const auto start = svg_file.find("<svg");
  std::string svg(start == std::string_view::npos ? std::string_view{} : svg_file.substr(start));
  const std::string prefix(id_prefix);
  for (const char quote : {'\'', '"'}) {
    const std::string q(1, quote);
    replace_all(svg, "id=" + q, "id=" + q + prefix);
    replace_all(svg, "href=" + q + "#", "href=" + q + "#" + prefix);
  }
  replace_all(svg, "url(#", "url(#" + prefix);
  while (!svg.empty() && (svg.back() == '\n' || svg.back() == ' ')) svg.pop_back();
  return svg;
}

GnuplotResult render_svg_figures(const std::vector<GnuplotFigure>& figures,
                                 const std::map<std::string, std::string>& data_files) {
  GnuplotResult result;
  if (figures.empty()) return result;
  const auto program = find_on_path("gnuplot");
  if (!program) {
    result.error = "gnuplot was not found on PATH (install the Debian package gnuplot-nox)";
    return result;
  }
  const ScratchDir scratch;
  if (scratch.path().empty()) {
    result.error =
        "cannot create a scratch directory for the plots in " + std::filesystem::temp_directory_path().string();
    return result;
  }
  std::ostringstream script;
  script << "set encoding utf8\n";
  for (const auto& figure : figures) {
    // noenhanced: names such as quadratic_drag or gyro.y^2 are printed as written, not as sub/superscripts.
    script << "reset\nset terminal svg size " << figure.width << ',' << figure.height
           << " font 'sans,12' noenhanced background rgb 'white'\n"
           << "set output " << gnuplot_quote(figure.name + ".svg") << '\n'
           << figure.commands << "\nunset output\n";
  }
  bool written = write_file(scratch.path() / "figures.gp", script.str());
  for (const auto& [name, content] : data_files) written = written && write_file(scratch.path() / name, content);
  if (!written) {
    result.error = "cannot write the plot data in " + scratch.path().string();
    return result;
  }
  std::string error;
  const int status = run_gnuplot(*program, scratch.path(), "figures.gp", "gnuplot.log", error);
  if (status != 0) {
    const std::string log = first_line(read_file(scratch.path() / "gnuplot.log"));
    result.error = status < 0 ? "cannot run " + program->string() + ": " + error
                              : "gnuplot failed (exit " + std::to_string(status) + ")" +
                                    (log.empty() ? std::string{} : ": " + log);
    return result;
  }
  for (const auto& figure : figures) {
    const std::string svg = read_file(scratch.path() / (figure.name + ".svg"));
    if (svg.find("<svg") == std::string::npos) {
      result.svgs.clear();
      result.error = "gnuplot wrote no figure " + figure.name;
      return result;
    }
    result.svgs.push_back(inline_svg(svg, figure.name + "_"));
  }
  return result;
}

}  // namespace imubridge::diagnose
