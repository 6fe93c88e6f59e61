-- telelink.lua: a Wireshark dissector for telelink traffic.
--
--   * "telelink": the bytes of a serial line (pcapng link type LINKTYPE_USER0,
--     147, as written by `--capture` on `linksim relay`, `serialsocket
--     listen|connect` and `linksim arm-server` over a serial port): Kermit
--     framing (MARK LEN SEQ TYPE DATA CHECK, normal and extended "long"
--     packets, block check types 1, 2 and 3 = CRC-16/KERMIT), the serial
--     socket's ARQ packet types (serialsocket/PROTOCOL.md) and Kermit file
--     transfer types (serialsocket/KERMIT.md).  The ARQ's data is put back
--     in sequence each way; a stream that is a tcpstream session (the arm
--     server over a serial line) has its command packets dissected too.
--   * "tlcmd": tcpstream's 216-byte packets (tcpstream/PROTOCOL.md): on
--     LINKTYPE_USER1 (148; `linksim arm-server --transport tcp --capture`) and
--     on TCP port 7010 (a plain tcpdump/Wireshark capture of the arm server).
--
-- Use:  tshark -X lua_script:contrib/wireshark/telelink.lua -r FILE.pcapng -V
-- or copy it to ~/.local/lib/wireshark/plugins/.
--
-- A capture chunk of a serial line need not hold whole packets: bytes of an
-- unfinished packet are carried to the next chunk of the same interface and
-- direction (the "carried" field says how many), so packets are shown in the
-- frame where they end.  Works with Lua 5.2 (Wireshark 3.x-4.2) and 5.3+.

----------------------------------------------------------------------------
-- bit operations on any Lua Wireshark ships with
----------------------------------------------------------------------------
local bxor, band, rshift
if bit32 then
    bxor, band, rshift = bit32.bxor, bit32.band, bit32.rshift
elseif bit then
    bxor, band, rshift = bit.bxor, bit.band, bit.rshift
else
    bxor, band, rshift = load(
        "return function(a, b) return a ~ b end, function(a, b) return a & b end, "
            .. "function(a, n) return a >> n end"
    )()
end

local SOH, CR = 0x01, 0x0D
local CMD_SIZE = 216
local MAX_CARRY = 9100 -- longest Kermit packet (9024 + header + EOL): more is noise

local function unchar(c) return c - 32 end

-- CRC-16/KERMIT: poly 0x1021 reflected (0x8408), init 0, no final XOR.
local function crc16_kermit(bytes, first, last)
    local crc = 0
    for i = first, last do
        crc = bxor(crc, bytes[i])
        for _ = 1, 8 do
            if band(crc, 1) == 1 then
                crc = bxor(rshift(crc, 1), 0x8408)
            else
                crc = rshift(crc, 1)
            end
        end
    end
    return crc
end

local function sum(bytes, first, last)
    local s = 0
    for i = first, last do s = s + bytes[i] end
    return s
end

-- The check characters of type 1, 2 or 3 over bytes[first..last], as a byte list.
local function check_chars(kind, bytes, first, last)
    if kind == 1 then
        local s = sum(bytes, first, last)
        return { band(s + rshift(band(s, 0xC0), 6), 0x3F) + 32 }
    elseif kind == 2 then
        local s = band(sum(bytes, first, last), 0xFFF)
        return { rshift(s, 6) + 32, band(s, 0x3F) + 32 }
    end
    local c = crc16_kermit(bytes, first, last)
    return { rshift(c, 12) + 32, band(rshift(c, 6), 0x3F) + 32, band(c, 0x3F) + 32 }, c
end

----------------------------------------------------------------------------
-- protocol "telelink": the serial line
----------------------------------------------------------------------------
local tl = Proto("telelink", "telelink serial line (Kermit framing, ARQ)")

tl.prefs.qctl = Pref.string("Control prefix (QCTL)", "#", "Kermit control prefix")
tl.prefs.qbin = Pref.string(
    "8th-bit prefix (QBIN)", "&",
    "Kermit 8th-bit prefix; empty when the link negotiated an 8-bit line"
)
tl.prefs.rept = Pref.string("Repeat prefix (REPT)", "~", "Kermit repeat prefix; empty for none")

local TYPE_NAMES = {
    I = "Init (connection request)", Y = "ACK", N = "NAK", D = "Data",
    Z = "End of stream (EOF)", E = "Error / abort",
    S = "Send-Init", F = "File header", A = "Attributes", B = "End of transmission",
    X = "Text header", R = "Receive-Init", G = "Generic command", C = "Host command",
    Q = "Reserved", T = "Reserved",
    d = "Data with sums (corrected data packet, PROTOCOL.md 15)",
    r = "Repair (the sums of a damaged D packet, PROTOCOL.md 15.6)",
}

local f = {
    carried = ProtoField.uint32("telelink.carried", "Bytes carried from earlier frames"),
    noise = ProtoField.bytes("telelink.noise", "Bytes outside packets"),
    noise_text = ProtoField.string("telelink.noise.text", "As text"),
    packet = ProtoField.bytes("telelink.packet", "Kermit packet"),
    mark = ProtoField.uint8("telelink.mark", "MARK", base.HEX),
    len = ProtoField.uint8("telelink.len", "LEN (chars after LEN through CHECK)"),
    extended = ProtoField.bool("telelink.extended", "Extended (long) packet"),
    lenx = ProtoField.uint16("telelink.lenx", "LENX (DATA + CHECK chars)"),
    hcheck = ProtoField.uint8("telelink.hcheck", "HCHECK (header check)", base.HEX),
    hcheck_good = ProtoField.bool("telelink.hcheck.good", "Header check good"),
    length = ProtoField.uint16("telelink.length", "Packet length (MARK..CHECK)"),
    seq = ProtoField.uint8("telelink.seq", "SEQ"),
    seq_long = ProtoField.uint32("telelink.seq.long", "Sequence number (18-bit, long sequence numbers)"),
    type = ProtoField.string("telelink.type", "TYPE"),
    type_name = ProtoField.string("telelink.type.name", "Type name"),
    data = ProtoField.bytes("telelink.data", "DATA (as sent)"),
    data_len = ProtoField.uint16("telelink.data.length", "DATA length (encoded)"),
    decoded = ProtoField.bytes("telelink.data.decoded", "DATA decoded"),
    decoded_len = ProtoField.uint16("telelink.data.decoded.length", "Decoded length"),
    decoded_text = ProtoField.string("telelink.data.text", "Decoded as text"),
    check = ProtoField.string("telelink.check", "CHECK"),
    check_type = ProtoField.uint8("telelink.check.type", "Block check type", base.DEC,
        { [1] = "1 (6-bit checksum)", [2] = "2 (12-bit checksum)", [3] = "3 (CRC-16/KERMIT)" }),
    check_value = ProtoField.uint16("telelink.check.value", "CRC-16/KERMIT", base.HEX),
    check_good = ProtoField.bool("telelink.check.good", "Check good"),
    eol = ProtoField.uint8("telelink.eol", "EOL", base.HEX),
    ack_next = ProtoField.uint32("telelink.ack.next", "Next expected (cumulative)"),
    ack_window = ProtoField.uint32("telelink.ack.window", "Advertised window"),
    ack_poll = ProtoField.bool("telelink.ack.poll", "Poll (answer at once)"),
    reason = ProtoField.string("telelink.reason", "Reason"),
    init = ProtoField.bytes("telelink.init", "Init parameters"),
    init_maxl = ProtoField.uint8("telelink.init.maxl", "MAXL"),
    init_time = ProtoField.uint8("telelink.init.time", "TIME (s)"),
    init_npad = ProtoField.uint8("telelink.init.npad", "NPAD"),
    init_eol = ProtoField.uint8("telelink.init.eol", "EOL", base.HEX),
    init_qctl = ProtoField.string("telelink.init.qctl", "QCTL"),
    init_qbin = ProtoField.string("telelink.init.qbin", "QBIN"),
    init_chkt = ProtoField.string("telelink.init.chkt", "CHKT"),
    init_rept = ProtoField.string("telelink.init.rept", "REPT"),
    init_capas = ProtoField.uint8("telelink.init.capas", "CAPAS", base.HEX),
    init_window = ProtoField.uint8("telelink.init.window", "WINDO"),
    init_maxlx = ProtoField.uint16("telelink.init.maxlx", "MAXLX (DATA + CHECK)"),
    init_sysid = ProtoField.string("telelink.init.sysid", "SYSID"),
    init_version = ProtoField.uint8("telelink.init.version", "telelink protocol version"),
    init_timeout = ProtoField.uint32("telelink.init.timeout_ms", "Initial timeout hint (ms)"),
    init_xcapas = ProtoField.uint8("telelink.init.xcapas", "XCAPAS (telelink capabilities)", base.HEX),
    init_long_window = ProtoField.uint32("telelink.init.long_window", "XWINDO (window with long sequence numbers)"),
}
tl.fields = {}
for _, field in pairs(f) do table.insert(tl.fields, field) end

local ef_bad_check = ProtoExpert.new("telelink.check.bad", "Block check failed",
    expert.group.CHECKSUM, expert.severity.ERROR)
local ef_bad_header = ProtoExpert.new("telelink.hcheck.bad", "Extended header check failed",
    expert.group.CHECKSUM, expert.severity.ERROR)
local ef_noise = ProtoExpert.new("telelink.noise.expert", "Bytes outside any packet",
    expert.group.MALFORMED, expert.severity.NOTE)
local ef_truncated = ProtoExpert.new("telelink.truncated", "Packet cut short by a new MARK",
    expert.group.MALFORMED, expert.severity.WARN)
tl.experts = { ef_bad_check, ef_bad_header, ef_noise, ef_truncated }

local frame_interface = Field.new("frame.interface_id")
local frame_direction = Field.new("frame.packet_flags_direction")

-- Per interface and direction: bytes of a packet not finished yet (first pass),
-- and per frame the bytes carried into it (so a re-dissection is the same).
local frame_interface_name = Field.new("frame.interface_name")

-- "NAME tx " / "NAME rx ": which port or connection, and which way (captures
-- from the relay have two ports, from the arm server one per connection).
local function direction_prefix()
    local name, dir = frame_interface_name(), frame_direction()
    local text = name and (tostring(name.value) .. " ") or ""
    if dir and dir.value == 1 then
        text = text .. "rx "
    elseif dir and dir.value == 2 then
        text = text .. "tx "
    end
    return text
end

local function stream_carry(name)
    local state = { pending = {}, into = {} }
    function state.key()
        local i, d = frame_interface(), frame_direction()
        return name .. ":" .. tostring(i and i.value or 0) .. ":" .. tostring(d and d.value or 0)
    end
    -- The buffer to dissect: carried bytes plus this frame's.
    function state.join(tvb, pinfo)
        local prefix
        if pinfo.visited then
            prefix = state.into[pinfo.number]
        else
            prefix = state.pending[state.key()]
            state.into[pinfo.number] = prefix
        end
        if prefix == nil or prefix:len() == 0 then return tvb, 0 end
        local joined = ByteArray.new()
        joined:append(prefix)
        joined:append(tvb:bytes())
        return joined:tvb("Reassembled " .. name), prefix:len()
    end
    -- Remember the unfinished tail (first pass only).
    function state.keep(buf, from, pinfo)
        if pinfo.visited then return end
        local rest = buf:len() - from
        if rest > 0 and rest <= MAX_CARRY then
            state.pending[state.key()] = buf:range(from, rest):bytes()
        else
            state.pending[state.key()] = nil
        end
    end
    function state.reset()
        state.pending, state.into = {}, {}
    end
    return state
end

local serial_carry = stream_carry("serial line")

local function prefix_byte(pref)
    if pref == nil or #pref ~= 1 then return nil end
    return string.byte(pref)
end

-- The 8th-bit prefix two QBIN fields agree on (Kermit protocol manual): a
-- prefix character (33-62, 96-126) that the other side repeats or answers
-- 'Y' to; false for none (both 'Y', an 'N', or two different characters).
local function agree_qbin(a, b)
    local function is_prefix(c) return c and ((c >= 33 and c <= 62) or (c >= 96 and c <= 126)) end
    if is_prefix(a) and (b == a or b == 89) then return a end
    if is_prefix(b) and a == 89 then return b end
    return false
end

-- Undo Kermit prefix encoding: [REPT count] [QBIN] [QCTL] char.
local function kermit_decode(bytes, first, last, agreed_qbin)
    local qctl, qbin, rept = prefix_byte(tl.prefs.qctl), prefix_byte(tl.prefs.qbin),
        prefix_byte(tl.prefs.rept)
    -- What the init exchange agreed (false: no 8th-bit prefixing, an 8-bit
    -- line), when the capture holds it; else the preference.
    if agreed_qbin ~= nil then qbin = agreed_qbin or nil end
    local out, i = {}, first
    while i <= last do
        local count = 1
        local c = bytes[i]
        if rept and c == rept and i + 1 <= last then
            count = unchar(bytes[i + 1])
            i = i + 2
            c = bytes[i]
        end
        local high = 0
        if c and qbin and c == qbin then
            high = 0x80
            i = i + 1
            c = bytes[i]
        end
        if c and qctl and c == qctl then
            i = i + 1
            c = bytes[i]
            if c then
                local low = band(c, 0x7F)
                if low >= 63 and low <= 95 then c = bxor(c, 64) end
            end
        end
        if c == nil then return nil end -- a prefix with nothing after it
        local byte = band(c, 0x7F) + (high ~= 0 and 0x80 or band(c, 0x80))
        for _ = 1, count do out[#out + 1] = string.char(byte) end
        i = i + 1
    end
    return table.concat(out)
end

local function printable(s)
    return (s:gsub("[^\32-\126]", function(ch) return string.format("\\x%02x", ch:byte()) end))
end

local dissect_cmd_tvb -- defined with tlcmd below

----------------------------------------------------------------------------
-- The serial socket's byte stream, each way: good D packets put back in
-- sequence order, duplicates dropped (serialsocket/PROTOCOL.md section 4).
-- When a stream starts with a tcpstream HELLO ("TL" 1), its 216-byte packets
-- are dissected in the frame whose data completed them.  Built on the first
-- pass, in frame order; later passes show what was stored per frame.
----------------------------------------------------------------------------
local arq = { streams = {}, frames = {} }
local ARQ_AHEAD = 32 -- sequence numbers at or after `expected` that are new (window <= 31)

function arq.reset()
    arq.streams, arq.frames = {}, {}
end

-- An init starts new sequence spaces (data from 1) both ways on that interface.
function arq.restart(interface)
    arq.streams["serial line:" .. interface .. ":1"] = nil -- the keys of stream_carry
    arq.streams["serial line:" .. interface .. ":2"] = nil
end

function arq.data(key, seq, data, frame, modulus)
    local s = arq.streams[key]
    if s == nil then
        s = { expected = 1, held = {}, buffer = "", mode = nil }
        arq.streams[key] = s
    end
    local ahead = modulus == 64 and ARQ_AHEAD or modulus / 2
    if (seq - s.expected) % modulus >= ahead or s.held[seq] ~= nil then return end
    s.held[seq] = data
    while s.held[s.expected] ~= nil do
        s.buffer = s.buffer .. s.held[s.expected]
        s.held[s.expected] = nil
        s.expected = (s.expected + 1) % modulus
    end
    if s.mode == nil and #s.buffer >= 3 then
        s.mode = s.buffer:sub(1, 3) == "TL\1" and "tcpstream" or "bytes"
    end
    if s.mode == "tcpstream" then
        while #s.buffer >= CMD_SIZE do
            arq.frames[frame] = arq.frames[frame] or {}
            table.insert(arq.frames[frame], s.buffer:sub(1, CMD_SIZE))
            s.buffer = s.buffer:sub(CMD_SIZE + 1)
        end
    elseif s.mode == "bytes" then
        s.buffer = "" -- not a command session: nothing more to decode
    end
end

-- n characters of 6 bits each (tochar), most significant first, from bytes[at].
local function base64_number(bytes, at, n)
    local v = 0
    for k = 0, n - 1 do v = v * 64 + unchar(bytes[at + k]) end
    return v
end

-- Long sequence numbers (18 bits), per interface: offered in the I, agreed
-- when the init's answer offers them too.  First pass: `active` follows the
-- capture; `at` remembers, per packet, what was in force for later passes.
local longseq = { offer = {}, active = {}, at = {}, qbin_offer = {}, qbin = {}, qbin_at = {} }
local LONG_MODULUS = 64 * 64 * 64

function longseq.reset()
    longseq.offer, longseq.active, longseq.at = {}, {}, {}
    longseq.qbin_offer, longseq.qbin, longseq.qbin_at = {}, {}, {}
end

local function add_init(tree, buf, dstart, dlen, bytes)
    local t = tree:add(f.init, buf:range(dstart, dlen))
    local fields = { f.init_maxl, f.init_time, f.init_npad, false, f.init_eol, f.init_qctl,
        f.init_qbin, f.init_chkt, f.init_rept, f.init_capas }
    for n = 1, math.min(dlen, 10) do
        local field, r, c = fields[n], buf:range(dstart + n - 1, 1), bytes[dstart + n]
        if field == f.init_qctl or field == f.init_qbin or field == f.init_chkt
            or field == f.init_rept then
            t:add(field, r)
        elseif field then
            t:add(field, r, unchar(c))
        end
    end
    -- After CAPAS (bit 1: another CAPAS byte follows) come WINDO, MAXLX1, MAXLX2.
    local p = 10
    while p <= dlen and band(unchar(bytes[dstart + p]), 1) == 1 do p = p + 1 end
    if p + 1 <= dlen then t:add(f.init_window, buf:range(dstart + p, 1), unchar(bytes[dstart + p + 1])) end
    if p + 3 <= dlen then
        t:add(f.init_maxlx, buf:range(dstart + p + 1, 2),
            unchar(bytes[dstart + p + 2]) * 95 + unchar(bytes[dstart + p + 3]))
    end
    -- CHKPNT, CHKINT (3), and WHATAMI at p+4..p+8; SYSID tochar(len) text at p+9.
    local s = p + 9
    if s <= dlen then
        local n = unchar(bytes[dstart + s])
        if n > 0 and s + n <= dlen then
            t:add(f.init_sysid, buf:range(dstart + s, n))
            local sysid = buf:range(dstart + s, n):string()
            local after = s + n + 1 -- WHATAMI2, VERSION, TIMEOUT (3 base-95 chars)
            if sysid == "TL" and after + 1 <= dlen then
                t:add(f.init_version, buf:range(dstart + after, 1), unchar(bytes[dstart + after + 1]))
                if after + 4 <= dlen then
                    local ms = 0
                    for k = 2, 4 do ms = ms * 95 + unchar(bytes[dstart + after + k]) end
                    t:add(f.init_timeout, buf:range(dstart + after + 1, 3), ms)
                end
                -- XCAPAS (bit 0: long sequence numbers), then XWINDO as three
                -- 6-bit characters (serialsocket/PROTOCOL.md section 9).
                if after + 5 <= dlen then
                    local xcapas = unchar(bytes[dstart + after + 5])
                    t:add(f.init_xcapas, buf:range(dstart + after + 4, 1), xcapas)
                    if band(xcapas, 1) == 1 and after + 8 <= dlen then
                        t:add(f.init_long_window, buf:range(dstart + after + 5, 3),
                            base64_number(bytes, dstart + after + 6, 3))
                        return true
                    end
                end
            end
        end
    end
    return false
end

-- One packet at buf[pos .. pos+total-1] (0-based), eol included when present.
local function add_packet(buf, pinfo, tree, bytes, pos, total, has_eol, summary)
    local extended = bytes[pos + 2] == 32
    local header = extended and 7 or 4 -- MARK LEN SEQ TYPE [LENX1 LENX2 HCHECK]
    local t = tree:add(f.packet, buf:range(pos, total + (has_eol and 1 or 0)))
    t:add(f.mark, buf:range(pos, 1))
    t:add(f.length, buf:range(pos, total), total)
    if extended then
        t:add(f.extended, buf:range(pos + 1, 1), true)
        t:add(f.len, buf:range(pos + 1, 1), 0)
    else
        t:add(f.len, buf:range(pos + 1, 1), unchar(bytes[pos + 2]))
    end
    local seq, type_char = unchar(bytes[pos + 3]), string.char(bytes[pos + 4])
    t:add(f.seq, buf:range(pos + 2, 1), seq)
    t:add(f.type, buf:range(pos + 3, 1))
    local name = TYPE_NAMES[type_char] or "Unknown type"
    if extended then
        t:add(f.lenx, buf:range(pos + 4, 2), unchar(bytes[pos + 5]) * 95 + unchar(bytes[pos + 6]))
        local want = check_chars(1, bytes, pos + 2, pos + 6)[1]
        local hi = t:add(f.hcheck, buf:range(pos + 6, 1))
        local good = want == bytes[pos + 7]
        t:add(f.hcheck_good, buf:range(pos + 6, 1), good)
        if not good then hi:add_proto_expert_info(ef_bad_header) end
    end
    -- Which block check: the first of 3, 1, 2 that matches; else report type 3.
    local kind, crc
    for _, k in ipairs({ 3, 1, 2 }) do
        if total - k >= header then
            local want, c = check_chars(k, bytes, pos + 2, pos + total - k)
            local ok = true
            for j = 1, k do
                if want[j] ~= bytes[pos + total - k + j] then ok = false end
            end
            if ok then kind, crc = k, c break end
        end
    end
    local good = kind ~= nil
    if not good then
        kind = 3
        local _, c = check_chars(3, bytes, pos + 2, pos + total - 3)
        crc = c
    end
    local dstart, dlen = pos + header, total - header - kind
    if dlen < 0 then dlen = 0 end
    local iface = frame_interface()
    iface = tostring(iface and iface.value or 0)
    local where = pinfo.number .. ":" .. pos
    local long
    if pinfo.visited then
        long = longseq.at[where] or false
    else
        long = longseq.active[iface] or false
        longseq.at[where] = long
    end
    local init = (type_char == "I" or type_char == "S" or (type_char == "Y" and seq == 0 and dlen >= 12))
        and dlen > 0
    -- Long sequence numbers: the data field starts with the 12 high bits.
    local full, width, modulus = seq, 1, 64
    if long and not init and dlen >= 2
        and (type_char == "D" or type_char == "Z" or type_char == "N" or type_char == "Y"
            or type_char == "d" or type_char == "r") then
        full = base64_number(bytes, dstart + 1, 2) * 64 + seq
        t:add(f.seq_long, buf:range(dstart, 2), full)
        dstart, dlen = dstart + 2, dlen - 2
        width, modulus = 3, LONG_MODULUS
    end
    local is_ack = type_char == "Y" and not init and (dlen == 2 * width or dlen == 2 * width + 1)
    -- The type's meaning (ARQ, serialsocket/PROTOCOL.md section 2).
    local words = type_char .. " " .. full
    if init and type_char == "Y" then
        name = "ACK of init (connection accepted; the acceptor's parameters)"
    elseif is_ack then
        name = "ACK"
        words = words .. " next=" .. base64_number(bytes, dstart + 1, width)
            .. " win=" .. base64_number(bytes, dstart + 1 + width, width)
    end
    t:add(f.type_name, buf:range(pos + 3, 1), name)
    if dlen > 0 then
        t:add(f.data, buf:range(dstart, dlen))
        t:add(f.data_len, buf:range(dstart, dlen), dlen)
    end
    local qbin
    if pinfo.visited then
        qbin = longseq.qbin_at[where]
    else
        qbin = longseq.qbin[iface]
        longseq.qbin_at[where] = qbin
    end
    if init then
        local offered = add_init(t, buf, dstart, dlen, bytes)
        if good and not pinfo.visited then
            local q = dlen >= 7 and bytes[dstart + 7] or nil
            if type_char == "I" then
                longseq.offer[iface], longseq.active[iface] = offered, false
                longseq.qbin_offer[iface], longseq.qbin[iface] = q, nil
            elseif type_char == "Y" then
                longseq.active[iface] = (longseq.offer[iface] or false) and offered
                longseq.qbin[iface] = agree_qbin(longseq.qbin_offer[iface], q)
            end
        end
    elseif is_ack then
        t:add(f.ack_next, buf:range(dstart, width), base64_number(bytes, dstart + 1, width))
        t:add(f.ack_window, buf:range(dstart + width, width),
            base64_number(bytes, dstart + 1 + width, width))
        t:add(f.ack_poll, buf:range(dstart, dlen), dlen == 2 * width + 1 and bytes[dstart + dlen] == 80)
    elseif dlen > 0 and (type_char == "D" or type_char == "E" or type_char == "F"
        or type_char == "X") then
        local decoded = kermit_decode(bytes, dstart + 1, dstart + dlen, qbin)
        if decoded ~= nil then
            local dtvb = ByteArray.new(decoded, true):tvb("Decoded DATA")
            t:add(f.decoded, dtvb:range(0, #decoded))
            t:add(f.decoded_len, buf:range(dstart, dlen), #decoded)
            if type_char == "E" then
                t:add(f.reason, buf:range(dstart, dlen), decoded)
                words = words .. " " .. printable(decoded)
            elseif type_char == "F" then
                words = words .. " " .. printable(decoded)
            else
                t:add(f.decoded_text, buf:range(dstart, dlen), printable(decoded:sub(1, 80)))
                words = words .. " " .. #decoded .. "B"
                if type_char == "D" and good and not pinfo.visited then
                    arq.data(serial_carry.key(), full, decoded, pinfo.number, modulus)
                end
            end
        end
    end
    local ci = t:add(f.check, buf:range(pos + total - kind, kind))
    t:add(f.check_type, buf:range(pos + total - kind, kind), kind)
    if kind == 3 then t:add(f.check_value, buf:range(pos + total - kind, kind), crc) end
    t:add(f.check_good, buf:range(pos + total - kind, kind), good)
    if not good then
        ci:add_proto_expert_info(ef_bad_check)
        words = words .. " [BAD CHECK]"
    end
    if type_char == "I" and good and not pinfo.visited then
        local i = frame_interface()
        arq.restart(tostring(i and i.value or 0))
    end
    if has_eol then t:add(f.eol, buf:range(pos + total, 1)) end
    t:set_text(string.format("Kermit %s seq=%d len=%d: %s", type_char, full, total, name))
    table.insert(summary, words)
end

function tl.dissector(tvb, pinfo, tree)
    pinfo.cols.protocol = "telelink"
    local buf, carried = serial_carry.join(tvb, pinfo)
    local n = buf:len()
    local root = tree:add(tl, buf:range(0, n))
    if carried > 0 then root:add(f.carried, buf:range(0, carried), carried) end
    local bytes = {}
    local raw = buf:range(0, n):raw() -- raw(): string() maps bytes >= 0x80 to U+FFFD
    for i = 1, n do bytes[i] = raw:byte(i) end -- 1-based copy; buf offsets are 0-based
    local summary = {}
    local pos = 0 -- 0-based offset into buf
    local noise_from = nil
    local function flush_noise(upto)
        if noise_from ~= nil and upto > noise_from then
            local r = buf:range(noise_from, upto - noise_from)
            local item = root:add(f.noise, r)
            item:add(f.noise_text, r, printable(r:string()))
            item:add_proto_expert_info(ef_noise)
            table.insert(summary, "noise " .. (upto - noise_from) .. "B")
        end
        noise_from = nil
    end
    local keep_from = n
    while pos < n do
        if bytes[pos + 1] == CR and noise_from == nil then
            -- The EOL of a packet that ended in an earlier chunk.
            root:add(f.eol, buf:range(pos, 1))
            pos = pos + 1
        elseif bytes[pos + 1] ~= SOH then
            if noise_from == nil then noise_from = pos end
            pos = pos + 1
        else
            -- Length of MARK..CHECK, or nil when the header is not here yet.
            local total, bad
            if pos + 2 > n then
                total = nil
            elseif bytes[pos + 2] == 32 then
                if pos + 7 <= n then
                    total = 7 + unchar(bytes[pos + 5]) * 95 + unchar(bytes[pos + 6])
                end
            else
                local l = unchar(bytes[pos + 2])
                if l >= 3 and l <= 94 then total = l + 2 else bad = true end
            end
            if bad then
                if noise_from == nil then noise_from = pos end
                pos = pos + 1
            else
                -- A new MARK inside the packet means this one was cut short.
                local limit = total and math.min(pos + total, n) or n
                local cut = nil
                for j = pos + 1, limit - 1 do
                    if bytes[j + 1] == SOH then cut = j break end
                end
                if cut ~= nil then
                    if noise_from == nil then noise_from = pos end
                    flush_noise(cut)
                    root:add_proto_expert_info(ef_truncated)
                    pos = cut
                elseif total == nil or pos + total > n then
                    flush_noise(pos)
                    keep_from = pos -- unfinished: carried to the next frame
                    break
                else
                    flush_noise(pos)
                    local has_eol = pos + total < n and bytes[pos + total + 1] == CR
                    add_packet(buf, pinfo, root, bytes, pos, total, has_eol, summary)
                    pos = pos + total + (has_eol and 1 or 0)
                end
            end
        end
    end
    flush_noise(math.min(pos, keep_from))
    serial_carry.keep(buf, keep_from, pinfo)
    for _, raw in ipairs(arq.frames[pinfo.number] or {}) do
        local packet = ByteArray.new(raw, true):tvb("tcpstream packet (serial socket data)")
        table.insert(summary, dissect_cmd_tvb(packet, pinfo, tree))
    end
    if keep_from < n then table.insert(summary, "(" .. (n - keep_from) .. "B carried)") end
    local arrow = direction_prefix()
    if #summary == 0 then summary = { "EOL" } end
    pinfo.cols.info:set(arrow .. table.concat(summary, ", "))
    return n - carried
end

----------------------------------------------------------------------------
-- protocol "tlcmd": tcpstream's 216-byte packets
----------------------------------------------------------------------------
local tc = Proto("tlcmd", "telelink tcpstream command packet")

local KINDS = {
    [1] = "HELLO", [2] = "CHALLENGE", [3] = "AUTH", [4] = "GRANT", [5] = "REFUSE",
    [6] = "COMMAND", [7] = "ACCEPTED", [8] = "COMPLETED", [9] = "FAILED",
    [10] = "TELEMETRY", [11] = "HEARTBEAT", [12] = "EMERGENCY_STOP", [13] = "BYE",
}
local CODES = {
    [1] = "REINITIALIZE", [2] = "STATUS", [3] = "OPEN_FINGERS", [4] = "CLOSE_FINGERS",
    [5] = "MOVE_TO_POSITION", [6] = "MOVE_JOINTS", [7] = "MOVE_JOINT", [8] = "TRANSFORM",
    [9] = "SQUEEZE", [10] = "WEIGH", [11] = "CHANGE_SPEED", [12] = "CENTER_FINGERS",
    [13] = "TERMINATE", [14] = "MOVE_CARTESIAN_DELTA", [15] = "MOVE_PATH",
    [16] = "EMERGENCY_STOP", [17] = "ADD_OBSTACLE",
}
local FAILURES = {
    [0] = "NONE", [1] = "JOINT_LIMIT", [2] = "UNREACHABLE", [3] = "SINGULAR",
    [4] = "COLLISION", [5] = "NO_OBJECT", [6] = "NOT_GRASPING", [7] = "STOPPED",
    [8] = "DEADMAN", [9] = "BAD_ARGUMENT", [10] = "SKIPPED", [15] = "ARM_FAULT",
    [32] = "BAD_PACKET", [33] = "UNKNOWN_COMMAND", [34] = "NOT_AUTHORIZED",
    [35] = "QUEUE_FULL", [36] = "TERMINATING", [37] = "EXPIRED",
}
local REFUSALS = {
    [1] = "BUSY", [2] = "NOT_AUTHORIZED", [3] = "SERVER_FULL", [4] = "BAD_HELLO",
    [5] = "HANDSHAKE_TIMEOUT", [6] = "SHUTTING_DOWN",
}
local CLOSES = {
    [0] = "NORMAL", [1] = "TERMINATED", [2] = "SILENCE", [3] = "GARBAGE",
    [4] = "HANDSHAKE_TIMEOUT", [5] = "AUTHENTICATION", [6] = "REFUSED", [7] = "PEER_EOF",
    [8] = "SHUTDOWN", [9] = "TAKEN_OVER", [10] = "IDLE", [11] = "STALLED",
}
local SLOTS = {
    "JOINT_1", "JOINT_2", "JOINT_3", "JOINT_4", "JOINT_5", "JOINT_6", "FINGER_OPENING",
    "P_X", "P_Y", "P_Z", "S_X", "S_Y", "S_Z", "A_X", "A_Y", "A_Z", "TACTILE", "ERROR",
}
local NUMERIC = { [6] = true, [7] = true, [8] = true, [10] = true, [11] = true, [12] = true }
local TEXT = { [5] = true, [9] = true, [13] = true }
local FEEDBACK = { [8] = true, [10] = true }

local g = {
    magic = ProtoField.string("tlcmd.magic", "Magic"),
    version = ProtoField.uint8("tlcmd.version", "Version"),
    kind = ProtoField.uint8("tlcmd.kind", "Kind", base.DEC, KINDS),
    flags = ProtoField.uint16("tlcmd.flags", "Flags", base.HEX),
    code = ProtoField.uint16("tlcmd.code", "Command code", base.DEC, CODES),
    status = ProtoField.uint16("tlcmd.status", "Status"),
    status_name = ProtoField.string("tlcmd.status.name", "Status name"),
    reserved = ProtoField.uint16("tlcmd.reserved", "Reserved"),
    request_id = ProtoField.uint32("tlcmd.request_id", "Request id"),
    counter = ProtoField.uint64("tlcmd.counter", "Counter"),
    aux = ProtoField.double("tlcmd.aux", "aux"),
    word = ProtoField.double("tlcmd.word", "w"),
    body = ProtoField.bytes("tlcmd.body", "Body"),
    text = ProtoField.string("tlcmd.text", "Text"),
    identity = ProtoField.string("tlcmd.hello.identity", "Identity"),
    incarnation = ProtoField.uint64("tlcmd.hello.incarnation", "Incarnation"),
    nonce = ProtoField.bytes("tlcmd.nonce", "Nonce"),
    tag = ProtoField.bytes("tlcmd.tag", "Tag (HMAC-SHA256, first 16 bytes)"),
}
tc.fields = {}
for _, field in pairs(g) do table.insert(tc.fields, field) end

local ef_bad_magic = ProtoExpert.new("tlcmd.bad_magic", "Not a tcpstream packet (bad magic)",
    expert.group.MALFORMED, expert.severity.ERROR)
tc.experts = { ef_bad_magic }

local function cstring(range)
    local s = range:string()
    local nul = s:find("\0", 1, true)
    return nul and s:sub(1, nul - 1) or s
end

-- One 216-byte packet; returns its one-line summary.
dissect_cmd_tvb = function(tvb, pinfo, tree)
    local t = tree:add(tc, tvb:range(0, CMD_SIZE))
    t:add(g.magic, tvb:range(0, 2))
    if tvb:range(0, 2):string() ~= "TL" then
        t:add_proto_expert_info(ef_bad_magic)
        return "not tcpstream"
    end
    local kind = tvb:range(3, 1):uint()
    local code, status = tvb:range(6, 2):uint(), tvb:range(8, 2):uint()
    local rid = tvb:range(12, 4):uint()
    t:add(g.version, tvb:range(2, 1))
    t:add(g.kind, tvb:range(3, 1))
    t:add(g.flags, tvb:range(4, 2))
    t:add(g.code, tvb:range(6, 2))
    local st = t:add(g.status, tvb:range(8, 2))
    local names = (kind == 9 and FAILURES) or (kind == 5 and REFUSALS) or (kind == 13 and CLOSES)
    if names then
        st:add(g.status_name, tvb:range(8, 2), names[status] or "unknown")
    end
    t:add(g.reserved, tvb:range(10, 2))
    t:add(g.request_id, tvb:range(12, 4))
    t:add(g.counter, tvb:range(16, 8))
    for i = 0, 3 do
        t:add(g.aux, tvb:range(24 + 8 * i, 8)):prepend_text("[" .. i .. "] ")
    end
    local body = tvb:range(56, 144)
    if NUMERIC[kind] then
        local b = t:add(g.body, body)
        for i = 0, 17 do
            local label = FEEDBACK[kind] and SLOTS[i + 1] or ("w[" .. i .. "]")
            b:add(g.word, tvb:range(56 + 8 * i, 8)):prepend_text(label .. " ")
        end
    elseif TEXT[kind] then
        t:add(g.text, body, cstring(body))
    elseif kind == 1 then
        t:add(g.identity, tvb:range(56, 32), cstring(tvb:range(56, 32)))
        t:add(g.incarnation, tvb:range(88, 8))
        t:add(g.nonce, tvb:range(96, 16))
    elseif kind == 2 then
        t:add(g.nonce, tvb:range(56, 16))
    else
        t:add(g.body, body)
    end
    t:add(g.tag, tvb:range(200, 16))
    local words = KINDS[kind] or ("kind " .. kind)
    words = words .. " #" .. tostring(tvb:range(16, 8):uint64())
    if rid ~= 0 then words = words .. " rid=" .. rid end
    if code ~= 0 then words = words .. " " .. (CODES[code] or tostring(code)) end
    if names then words = words .. " " .. (names[status] or tostring(status)) end
    t:set_text("tcpstream " .. words)
    return words
end

local stream_carry_cmd = stream_carry("tcpstream")

function tc.dissector(tvb, pinfo, tree)
    pinfo.cols.protocol = "tlcmd"
    local summary = {}
    if pinfo.can_desegment > 0 then
        -- Over TCP: let TCP reassemble whole 216-byte packets.
        local off, n = 0, tvb:len()
        while off < n do
            if n - off < CMD_SIZE then
                pinfo.desegment_offset = off
                pinfo.desegment_len = CMD_SIZE - (n - off)
                break
            end
            table.insert(summary, dissect_cmd_tvb(tvb:range(off, CMD_SIZE):tvb(), pinfo, tree))
            off = off + CMD_SIZE
        end
        pinfo.cols.info:set(table.concat(summary, ", "))
        return n
    end
    -- A capture of a stream (LINKTYPE_USER1): carry partial packets ourselves.
    local buf, carried = stream_carry_cmd.join(tvb, pinfo)
    local n, off = buf:len(), 0
    while n - off >= CMD_SIZE do
        table.insert(summary, dissect_cmd_tvb(buf:range(off, CMD_SIZE):tvb(), pinfo, tree))
        off = off + CMD_SIZE
    end
    stream_carry_cmd.keep(buf, off, pinfo)
    if off < n then table.insert(summary, "(" .. (n - off) .. "B carried)") end
    local arrow = direction_prefix()
    pinfo.cols.info:set(arrow .. table.concat(summary, ", "))
    return n - carried
end

function tl.init()
    serial_carry.reset()
    arq.reset()
    longseq.reset()
    stream_carry_cmd.reset()
end

local encaps = wtap_encaps or wtap
local wtap_table = DissectorTable.get("wtap_encap")
wtap_table:add(encaps.USER0, tl)
wtap_table:add(encaps.USER1, tc)
DissectorTable.get("tcp.port"):add(7010, tc)
