// `imubridge sync` against a real PostgreSQL server (tests/postgres_server.hpp): a session copied whole and bit for
// bit, a sync killed with SIGKILL half-way and resumed, two stations in one archive, reruns that send nothing, a
// session synced while it is still being recorded, the archive down, and every example query of docs/storage.md
// run on the archive.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <bit>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "store/sqlite.hpp"
#include "store/store.hpp"
#include "tests/support/postgres_server.hpp"
#include "tests/support/run_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace imubridge::test {
namespace {

namespace fs = std::filesystem;

// One server for the whole file (starting one takes a second or two); each test has its own database.
PostgresServer& server() {
  static PostgresServer instance;
  return instance;
}

std::string fresh_database() {
  static int counter = 0;
  const std::string name = "archive_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
  server().create_database(name);
  return name;
}

std::string trimmed(std::string text) {
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  return text;
}

std::int64_t archive_int(const std::string& database, const std::string& sql) {
  return std::stoll(trimmed(server().psql(database, sql)));
}

// A recorded session with samples and chunks (sim --db: the simulator's truth as reference) and a run's estimates
// (replay). Returns nothing: it is session 1 of a fresh file.
void record_session(const fs::path& db, int seed, double seconds, int rate_hz) {
  const auto sim = run_imubridge("sim --db " + db.string() + " --seed " + std::to_string(seed) + " --duration " +
                                 std::to_string(seconds) + " --rate " + std::to_string(rate_hz));
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const auto replay = run_imubridge("replay --db " + db.string() + " --session 1");
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
}

std::int64_t local_count(const fs::path& db, const std::string& sql) {
  const store::Database database(db, /*read_only=*/true);
  return database.query_int(sql);
}

// `imubridge <args>` as a child process, its stderr into `stderr_path`.
pid_t spawn(const std::vector<std::string>& args, const fs::path& stderr_path) {
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  if (!std::freopen(stderr_path.c_str(), "w", stderr) || !std::freopen("/dev/null", "w", stdout)) ::_exit(127);
  std::vector<char*> argv{const_cast<char*>(IMUBRIDGE_BIN)};
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  ::execv(IMUBRIDGE_BIN, argv.data());
  ::_exit(127);
}

// Polls `done` until it holds, for at most `limit`; returns whether it did.
bool eventually(const std::function<bool()>& done, std::chrono::seconds limit = std::chrono::seconds(20)) {
  for (const auto deadline = std::chrono::steady_clock::now() + limit; !done();) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// Every value of a session, bit for bit, in the order a reader gets it, with links and runs by name and order
// rather than by id (a restored session is renumbered by the file it lands in).
class Digest {
 public:
  void add(std::int64_t v) { bytes(&v, sizeof v); }
  void add(double v) { add(std::bit_cast<std::int64_t>(v)); }
  void add(const std::string& s) {
    add(static_cast<std::int64_t>(s.size()));
    bytes(s.data(), s.size());
  }
  template <typename T, std::size_t N>
  void add(const std::array<T, N>& values) {
    for (const T& v : values)
      add(static_cast<std::conditional_t<std::is_floating_point_v<T>, double, std::int64_t>>(v));
  }
  std::uint64_t value() const { return hash_; }

 private:
  void bytes(const void* data, std::size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) hash_ = (hash_ ^ p[i]) * 1099511628211ull;
  }
  std::uint64_t hash_ = 14695981039346656037ull;
};

struct SessionDigest {
  std::uint64_t value = 0;
  std::int64_t samples = 0, chunks = 0, estimates = 0, events = 0, reference = 0;
};

SessionDigest digest_session(const fs::path& db, std::int64_t session, bool with_chunks = true) {
  const store::Store store(db, {.read_only = true});
  Digest d;
  SessionDigest result;
  for (const auto& s : store.sessions()) {
    if (s.id != session) continue;
    d.add(s.info.kind), d.add(s.info.source), d.add(s.info.config), d.add(s.info.started_wall_ns);
    d.add(s.info.software_version), d.add(s.ended_wall_ns.value_or(-1));
  }
  std::map<std::int64_t, std::string> link_names;
  for (const auto& l : store.links(session)) {
    link_names[l.id] = l.name;
    d.add(l.name), d.add(l.protocol), d.add(l.device);
  }
  if (with_chunks) {
    store.for_each_chunk(session, std::nullopt, [&](const store::Chunk& c) {
      d.add(link_names.at(c.link_id)), d.add(static_cast<std::int64_t>(c.direction)), d.add(c.recv_mono_ns);
      d.add(c.recv_wall_ns), d.add(std::string(c.bytes.begin(), c.bytes.end()));
      ++result.chunks;
    });
  }
  store.for_each_sample(session, std::nullopt, [&](const protocol::Sample& s) {
    d.add(link_names.at(s.link_id)), d.add(static_cast<std::int64_t>(s.seq)), d.add(s.device_time_us);
    d.add(s.recv_mono_ns), d.add(s.accel), d.add(s.gyro), d.add(s.mag), d.add(s.temperature_c);
    d.add(std::int64_t{s.has_mag}), d.add(std::int64_t{s.has_temperature}), d.add(std::int64_t{s.has_raw});
    d.add(s.raw);
    ++result.samples;
  });
  for (const auto& e : store.events(session)) {
    d.add(e.link_id ? link_names.at(*e.link_id) : std::string("-")), d.add(e.mono_ns), d.add(e.wall_ns);
    d.add(e.kind), d.add(e.count), d.add(e.detail);
    ++result.events;
  }
  for (const auto& r : store.runs(session)) {
    d.add(r.info.kind), d.add(r.info.params_json), d.add(r.info.created_wall_ns), d.add(r.info.software_version);
    store.for_each_estimate(r.id, [&](const store::Estimate& e) {
      d.add(link_names.at(e.link_id)), d.add(static_cast<std::int64_t>(e.seq));
      for (double v : {e.t_s, e.fx, e.fy, e.vx, e.vy, e.var_vx, e.var_vy}) d.add(v);
      ++result.estimates;
    });
  }
  store.for_each_reference(session, [&](const store::ReferenceRow& r) {
    d.add(r.t_ns), d.add(r.position), d.add(r.quat_wxyz), d.add(std::int64_t{r.velocity.has_value()});
    if (r.velocity) d.add(*r.velocity);
    ++result.reference;
  });
  result.value = d.value();
  return result;
}

// Brings station's session back from the archive into a fresh file and returns the new file's session digest.
SessionDigest round_trip(const std::string& database, const std::string& station, std::int64_t session,
                         const fs::path& into, bool with_chunks = true) {
  const auto back = run_imubridge("sync --from " + server().url(database) + " --station " + station + " --session " +
                                  std::to_string(session) + " --db " + into.string());
  EXPECT_EQ(back.exit_code, 0) << back.err;
  return digest_session(into, std::stoll(back.out), with_chunks);
}

void expect_same(const SessionDigest& a, const SessionDigest& b) {
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.chunks, b.chunks);
  EXPECT_EQ(a.estimates, b.estimates);
  EXPECT_EQ(a.events, b.events);
  EXPECT_EQ(a.reference, b.reference);
  EXPECT_EQ(a.value, b.value) << "same counts, different values";
}

// The archive's rows of a station, per table, each key once.
void expect_archive_counts(const std::string& database, const std::string& station, const fs::path& db,
                           bool with_chunks) {
  for (const std::string table : {"samples", "events", "reference", "chunks", "links", "runs", "estimates"}) {
    const std::int64_t local = table == "chunks" && !with_chunks ? 0 : local_count(db, "SELECT count(*) FROM " + table);
    const std::string where = " FROM " + table + " WHERE station = '" + station + "'";
    EXPECT_EQ(archive_int(database, "SELECT count(*)" + where), local) << table;
    EXPECT_EQ(archive_int(database, "SELECT count(DISTINCT (session_id, id))" + where), local) << table;
  }
  // Integers add up exactly on both sides: a cheap second check of the values, independent of the round trip.
  EXPECT_EQ(trimmed(server().psql(database,
                                  "SELECT sum(seq), sum(device_time_us), sum(recv_mono_ns) FROM samples "
                                  "WHERE station = '" +
                                      station + "'")),
            std::to_string(local_count(db, "SELECT sum(seq) FROM samples")) + "|" +
                std::to_string(local_count(db, "SELECT sum(device_time_us) FROM samples")) + "|" +
                std::to_string(local_count(db, "SELECT sum(recv_mono_ns) FROM samples")));
}

TEST(CliSync, ASyncedSessionIsInTheArchiveBitForBit) {
  TempDir dir;
  record_session(dir / "gs.db", 3, 5, 400);
  const std::string database = fresh_database();
  const auto sync = run_imubridge("sync --to " + server().url(database) + " --db " + (dir / "gs.db").string() +
                                  " --station gs1 --chunks");
  ASSERT_EQ(sync.exit_code, 0) << sync.err;
  EXPECT_NE(sync.err.find("1 sessions added, 1 ended"), std::string::npos) << sync.err;
  expect_archive_counts(database, "gs1", dir / "gs.db", /*with_chunks=*/true);
  const SessionDigest source = digest_session(dir / "gs.db", 1);
  EXPECT_GT(source.samples, 1000);
  EXPECT_GT(source.estimates, 1000);
  EXPECT_GT(source.chunks, 0);
  EXPECT_GT(source.reference, 0);
  expect_same(round_trip(database, "gs1", 1, dir / "back.db"), source);
  // The restored session is a session like any other: replay reproduces its run bit for bit.
  const auto replay = run_imubridge("replay --db " + (dir / "back.db").string() + " --session 1");
  EXPECT_EQ(replay.exit_code, 0) << replay.err;
}

TEST(CliSync, ASyncKilledHalfWayResumesWithoutLossOrDuplicates) {
  TempDir dir;
  record_session(dir / "gs.db", 5, 40, 1000);  // 40,000 samples, as many estimates, chunks and reference rows
  const std::int64_t samples = local_count(dir / "gs.db", "SELECT count(*) FROM samples");
  const std::string database = fresh_database();
  const std::string args[] = {"sync",      "--to", server().url(database), "--db", (dir / "gs.db").string(),
                              "--station", "gs1",  "--batch-rows",         "250",  "--chunks"};
  // Killed once some batches are in and the copy is well under way: where exactly is drawn from a fixed seed.
  std::mt19937 random(20240611);
  const std::int64_t kill_after = std::uniform_int_distribution<std::int64_t>(1000, samples / 2)(random);
  const pid_t pid = spawn({std::begin(args), std::end(args)}, "/dev/null");
  std::int64_t copied = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    // Before the schema exists the query fails: nothing copied yet.
    try {
      copied = archive_int(database, "SELECT count(*) FROM samples");
    } catch (const std::runtime_error&) {
      copied = 0;
    }
    if (copied >= kill_after) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the sync ended before it was killed: make the session bigger";
  const std::int64_t at_kill = archive_int(database, "SELECT count(*) FROM samples");
  EXPECT_GE(at_kill, kill_after);
  EXPECT_LT(at_kill, samples);
  EXPECT_EQ(archive_int(database, "SELECT count(*) FROM sessions WHERE ended_wall_ns IS NOT NULL"), 0)
      << "a session is marked ended before all its rows are in";

  const auto resumed = run_imubridge("sync --to " + server().url(database) + " --db " + (dir / "gs.db").string() +
                                     " --station gs1 --chunks");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
  // Only what was missing was sent.
  EXPECT_NE(resumed.err.find("; " + std::to_string(samples - at_kill) + " samples,"), std::string::npos)
      << resumed.err << " (killed at " << at_kill << " of " << samples << ")";
  expect_archive_counts(database, "gs1", dir / "gs.db", /*with_chunks=*/true);
  expect_same(round_trip(database, "gs1", 1, dir / "back.db"), digest_session(dir / "gs.db", 1));
}

TEST(CliSync, TwoStationsKeepTheirSessionsApart) {
  TempDir dir;
  record_session(dir / "a.db", 11, 2, 200);
  record_session(dir / "b.db", 12, 3, 200);  // also its session 1, another flight
  const std::string database = fresh_database();
  for (const char* station : {"a", "b"}) {
    const auto sync = run_imubridge("sync --to " + server().url(database) + " --db " +
                                    (dir / (std::string(station) + ".db")).string() + " --station " + station);
    ASSERT_EQ(sync.exit_code, 0) << sync.err;
  }
  EXPECT_EQ(trimmed(server().psql(database, "SELECT station, id FROM sessions ORDER BY station")), "a|1\nb|1");
  expect_archive_counts(database, "a", dir / "a.db", /*with_chunks=*/false);
  expect_archive_counts(database, "b", dir / "b.db", /*with_chunks=*/false);
  expect_same(round_trip(database, "a", 1, dir / "a_back.db", false), digest_session(dir / "a.db", 1, false));
  expect_same(round_trip(database, "b", 1, dir / "b_back.db", false), digest_session(dir / "b.db", 1, false));

  // A second store under a name already taken is refused, not mixed into the other station's session.
  const auto clash =
      run_imubridge("sync --to " + server().url(database) + " --db " + (dir / "b.db").string() + " --station a");
  EXPECT_EQ(clash.exit_code, 1);
  EXPECT_EQ(count_lines(clash.err), 1) << clash.err;
  EXPECT_NE(clash.err.find("station 'a' session 1 in the archive is another session"), std::string::npos) << clash.err;
  expect_archive_counts(database, "a", dir / "a.db", /*with_chunks=*/false);
}

TEST(CliSync, ARerunSendsOnlyWhatIsNew) {
  TempDir dir;
  record_session(dir / "gs.db", 7, 2, 200);
  const std::string database = fresh_database();
  const std::string sync =
      "sync --to " + server().url(database) + " --db " + (dir / "gs.db").string() + " --station gs1";
  ASSERT_EQ(run_imubridge(sync).exit_code, 0);
  const std::string statistics = "SELECT sum(n_tup_ins + n_tup_upd + n_tup_del) FROM pg_stat_user_tables";
  const std::int64_t writes_before = archive_int(database, statistics);
  const auto again = run_imubridge(sync);
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.err.find("nothing new, the archive is up to date"), std::string::npos) << again.err;
  expect_archive_counts(database, "gs1", dir / "gs.db", /*with_chunks=*/false);
  // The server's own count of rows written: the statistics of a rerun's transactions would show any row it sent.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // the statistics reach the view within a second
  EXPECT_EQ(archive_int(database, statistics), writes_before);

  // What is new in a session synced through is still found: a replay's run, and the chunks once asked for.
  ASSERT_EQ(run_imubridge("replay --db " + (dir / "gs.db").string() + " --session 1").exit_code, 0);
  const auto replayed = run_imubridge(sync);
  const std::int64_t run_2 = local_count(dir / "gs.db", "SELECT count(*) FROM estimates WHERE run_id = 2");
  EXPECT_NE(replayed.err.find(" 0 samples, " + std::to_string(run_2) + " estimates,"), std::string::npos)
      << replayed.err;
  const auto with_chunks = run_imubridge(sync + " --chunks");
  EXPECT_NE(with_chunks.err.find(" " + std::to_string(local_count(dir / "gs.db", "SELECT count(*) FROM chunks")) +
                                 " chunks,"),
            std::string::npos)
      << with_chunks.err;
  expect_archive_counts(database, "gs1", dir / "gs.db", /*with_chunks=*/true);
  EXPECT_NE(run_imubridge(sync + " --chunks").err.find("nothing new"), std::string::npos);
}

TEST(CliSync, ASessionStillRecordingIsSyncedAsFarAsItGoesThenFinished) {
  TempDir dir;
  const fs::path db = dir / "live.db";
  store::Store store(db);
  const std::int64_t session = store.begin_session({.kind = "live", .source = "test", .started_wall_ns = 1000});
  const std::int64_t link = store.add_link(session, "imu0", "imubridge", "/dev/null");
  const auto append = [&](int from, int to) {
    for (int i = from; i < to; ++i) {
      protocol::Sample s;
      s.link_id = link;
      s.seq = static_cast<std::uint64_t>(i);
      s.accel = {0.0, -0.0, 9.81 + i};
      store.append_sample(session, s);
    }
    store.commit();
  };
  append(0, 300);
  const std::string database = fresh_database();
  const std::string sync = "sync --to " + server().url(database) + " --db " + db.string() + " --station gs1";
  ASSERT_EQ(run_imubridge(sync).exit_code, 0);
  EXPECT_EQ(archive_int(database, "SELECT count(*) FROM samples"), 300);
  EXPECT_EQ(trimmed(server().psql(database, "SELECT ended_wall_ns IS NULL FROM sessions")), "t");
  append(300, 700);
  store.end_session(session, 5000);
  const auto finished = run_imubridge(sync);
  ASSERT_EQ(finished.exit_code, 0) << finished.err;
  EXPECT_NE(finished.err.find("0 sessions added, 1 ended; 400 samples,"), std::string::npos) << finished.err;
  EXPECT_EQ(archive_int(database, "SELECT count(*) FROM samples"), 700);
  EXPECT_EQ(archive_int(database, "SELECT ended_wall_ns FROM sessions"), 5000);
  // -0.0 stays -0.0 (signbit), as the store keeps it.
  EXPECT_EQ(trimmed(server().psql(database,
                                  "SELECT count(*) FROM samples WHERE ay = 0 AND "
                                  "float8send(ay) = float8send('-0'::float8)")),
            "700");
}

// The daemon's [sync]: started while the archive is down (one line per attempt, recording unaffected), it syncs
// once the archive is up, while recording; what it had not sent when it stopped, the next sync sends.
TEST(CliSync, TheDaemonSyncsWhileRecordingAndWaitsForTheArchive) {
  TempDir dir;
  PostgresServer archive;  // its own: this test stops and starts it
  archive.create_database("fleet");
  archive.stop();
  const fs::path db = dir / "live.db";
  {
    std::ofstream config(dir / "imubridge.toml");
    config << "[store]\npath = \"" << db.string() << "\"\n[sync]\nto = \"" << archive.url("fleet")
           << "\"\nstation = \"gs1\"\ninterval_s = 1\n";
  }
  const fs::path pty = dir / "imu";
  const pid_t sim = spawn({"sim", "--pty", pty.string(), "--duration", "60", "--speed", "2"}, dir / "sim.log");
  ASSERT_TRUE(eventually([&] { return fs::exists(pty); }));
  const pid_t run =
      spawn({"run", "--config", (dir / "imubridge.toml").string(), "--link", "imu=" + pty.string() + ":imubridge"},
            dir / "run.log");
  const auto log = [&] { return slurp(dir / "run.log"); };
  ASSERT_TRUE(eventually([&] { return log().find("archive sync: " + archive.url("fleet")) != std::string::npos; }))
      << log();
  const std::string failure = log().substr(log().find("archive sync: " + archive.url("fleet")));
  EXPECT_NE(failure.find("Connection refused"), std::string::npos) << failure;
  EXPECT_NE(failure.find("; retrying in 1 s\n"), std::string::npos) << "one line per failed pass: " << failure;

  archive.start();
  ASSERT_TRUE(eventually([&] { return log().find("reachable again") != std::string::npos; })) << log();
  const auto archived = [&] {
    return std::stoll(trimmed(archive.psql("fleet", "SELECT count(*) FROM samples WHERE station = 'gs1'")));
  };
  ASSERT_TRUE(eventually([&] { return archived() > 0; }));
  const std::int64_t while_recording = archived();
  ASSERT_TRUE(eventually([&] { return archived() > while_recording; })) << "the second pass sent nothing new";
  ::kill(run, SIGTERM);
  ::kill(sim, SIGTERM);
  int status = 0;
  ::waitpid(run, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log();
  ::waitpid(sim, nullptr, 0);

  const auto rest = run_imubridge("sync --to " + archive.url("fleet") + " --db " + db.string() + " --station gs1");
  ASSERT_EQ(rest.exit_code, 0) << rest.err;
  EXPECT_NE(rest.err.find("0 sessions added, 1 ended"), std::string::npos) << rest.err;
  const SessionDigest local = digest_session(db, 1, false);
  EXPECT_GT(local.samples, while_recording);
  const auto back = run_imubridge("sync --from " + archive.url("fleet") + " --station gs1 --session 1 --db " +
                                  (dir / "back.db").string());
  ASSERT_EQ(back.exit_code, 0) << back.err;
  expect_same(digest_session(dir / "back.db", 1, false), local);
}

TEST(CliSync, AnArchiveDownIsOneLineAndAFailure) {
  TempDir dir;
  record_session(dir / "gs.db", 9, 1, 100);
  const std::string url = "postgresql://postgres:hunter2@127.0.0.1:" + std::to_string(free_loopback_port()) + "/x";
  const auto sync = run_imubridge("sync --to '" + url + "' --db " + (dir / "gs.db").string());
  EXPECT_EQ(sync.exit_code, 1);
  EXPECT_EQ(count_lines(sync.err), 1) << sync.err;
  EXPECT_NE(sync.err.find("postgresql://postgres:***@127.0.0.1"), std::string::npos) << sync.err;
  EXPECT_NE(sync.err.find("Connection refused"), std::string::npos) << sync.err;
  EXPECT_EQ(sync.err.find("hunter2"), std::string::npos) << "the password is shown: " << sync.err;
}

TEST(CliSync, TheDocsQueriesRunOnTheArchive) {
  TempDir dir;
  record_session(dir / "gs.db", 13, 2, 200);
  const std::string database = fresh_database();
  ASSERT_EQ(run_imubridge("sync --to " + server().url(database) + " --db " + (dir / "gs.db").string() +
                          " --station gs1 --chunks")
                .exit_code,
            0);
  // The ```sql block under "### Example queries on the archive" in docs/storage.md, statement by statement.
  const std::string docs = slurp(fs::path(IMUBRIDGE_SOURCE_DIR) / "docs" / "storage.md");
  const auto heading = docs.find("### Example queries on the archive");
  ASSERT_NE(heading, std::string::npos);
  const auto begin = docs.find("```sql\n", heading) + 7;
  const std::string block = docs.substr(begin, docs.find("```", begin) - begin);
  int statements = 0, with_rows = 0;
  std::string statement;
  for (std::size_t from = 0, semicolon; (semicolon = block.find(';', from)) != std::string::npos;
       from = semicolon + 1) {
    statement = block.substr(from, semicolon - from);
    if (statement.find_first_not_of(" \n") == std::string::npos) continue;
    // psql's error, if any, is the exception's message. Some rightly find nothing here (no gaps, no twinless
    // estimate: a sim session has neither), but most must find rows, or their station and session were wrong.
    with_rows += trimmed(server().psql(database, statement)).empty() ? 0 : 1;
    ++statements;
  }
  EXPECT_EQ(statements, 8);
  EXPECT_GE(with_rows, 6);
}

}  // namespace
}  // namespace imubridge::test
